"""UPDATE_BEGIN, UPDATE_DATA, UPDATE_VERIFY, UPDATE_ACTIVATE, UPDATE_CONFIRM, UPDATE_STATUS (SPEC §14)
over the update service (boot/update_service.py). ACTIVATE replies first, then the unit reboots."""
from __future__ import annotations

import functools
import threading
from typing import Callable

from stereocam.protocol import messages as m
from stereocam.protocol.errors import ErrorCode

from ..boot.update_service import UpdateService
from ..calibration.flash import FlashError, PowerLossError
from ..link_layer.dispatcher import Handler
from ..link_layer.refusal import Refusal

REBOOT_DELAY = 0.05  # s between the ACTIVATE reply and the reboot (the reply leaves first)


def _refusals(fn: Callable) -> Callable:
    """A flash failure → NACK STORAGE; a power cut turns the unit off (refusals NACK themselves)."""

    @functools.wraps(fn)
    def wrapper(self: "UpdateHandlers", msg: m.Message) -> m.Message:
        try:
            return fn(self, msg)
        except PowerLossError:
            self._power_cut()  # the unit is off: no reply leaves it
            raise
        except FlashError as exc:
            raise Refusal(ErrorCode.STORAGE, f"flash failed ({exc}); the boot state is unchanged") from exc
    return wrapper


class UpdateHandlers:
    def __init__(self, service: UpdateService, reboot: Callable[[], None], power_cut: Callable[[], None]):
        self.service = service
        self._reboot = reboot
        self._power_cut = power_cut

    def handlers(self) -> dict[int, Handler]:
        T = m.MsgType
        return {T.UPDATE_BEGIN: self.begin, T.UPDATE_DATA: self.data, T.UPDATE_VERIFY: self.verify,
                T.UPDATE_ACTIVATE: self.activate, T.UPDATE_CONFIRM: self.confirm, T.UPDATE_STATUS: self.status}

    @_refusals
    def begin(self, msg: m.UpdateBegin) -> m.UpdateBegun:
        s = self.service.begin(msg.size, msg.sha256, bool(msg.flags & m.BEGIN_REPLACE))
        return m.UpdateBegun(s.slot, s.total_received, s.size)

    @_refusals
    def data(self, msg: m.UpdateData) -> m.UpdateWritten:
        s = self.service.data(msg.offset, msg.data)
        return m.UpdateWritten(s.slot, s.total_received, s.size)

    @_refusals
    def verify(self, _: m.Message) -> m.UpdateVerified:
        slot, _image = self.service.verify()
        return m.UpdateVerified(self.service.slot_info(slot))

    @_refusals
    def activate(self, _: m.Message) -> m.UpdateActivating:
        slot = self.service.activate()
        threading.Timer(REBOOT_DELAY, self._reboot).start()
        return m.UpdateActivating(self.service.slot_info(slot))

    @_refusals
    def confirm(self, _: m.Message) -> m.UpdateConfirmed:
        return m.UpdateConfirmed(self.service.slot_info(self.service.confirm()))

    @_refusals
    def status(self, _: m.Message) -> m.UpdateState:
        svc, booted = self.service, self.service.booted
        s = svc.session
        state = svc.states.read()
        return m.UpdateState(0xFF if booted.slot is None else booted.slot, booted.mode,
                             s.total_received if s else 0, s.size if s else 0, s.sha256 if s else bytes(32),
                             state.counter if state else 0, tuple(svc.slot_info(i) for i in (0, 1)))
