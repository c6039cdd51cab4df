"""The update service of the running firmware (and of recovery): transfer into the slot that is
not running, verify, activate, confirm (SPEC §14.3). The session lives in RAM: a new host can
resume it (same size and hash) while the unit stays powered; a reboot or power cut ends it.

Refusals raise ``UpdateRefused`` and leave the boot state as it was. The image header is checked
(length, target, signing key, security counter) before a single flash byte is changed. The transfer
is held in RAM and written to the slot that is not running only once it verifies (hash, signature,
counter), so a refused image (a genuine header over garbage) leaves that slot's image, the
fallback, as it was.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field, replace

from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.firmware_image import (HEADER_LEN, FirmwareImage, ImageError, ImageFault, check_length,
                                               key_id, parse_header)
from stereocam.protocol.update_messages import BootMode, SlotInfo, SlotState

from ..link_layer.refusal import Refusal
from .boot_stage import Booted
from .boot_state import BootState, BootStateStore
from .slots import Slots


class UpdateRefused(Refusal):
    """A request the update service will not carry out: the firmware's one refusal, NACKed by the
    dispatcher like every other."""

    def __init__(self, code: ErrorCode, message: str):
        super().__init__(code, message)


@dataclass
class Session:
    slot: int
    size: int
    sha256: bytes
    received: bytearray = field(default_factory=bytearray)  # the image so far, held until it verifies
    verified: FirmwareImage | None = None

    @property
    def total_received(self) -> int:
        return len(self.received)


class UpdateService:
    def __init__(self, slots: Slots, states: BootStateStore, booted: Booted):
        self.slots = slots
        self.states = states
        self.booted = booted
        self.flash = slots.flash
        self.session: Session | None = None

    def _state(self) -> BootState:
        return self.states.read() or BootState()

    # -- transfer -------------------------------------------------------------------------------
    def begin(self, size: int, sha256: bytes, replace_session: bool) -> Session:
        s = self.session
        if s is not None and (s.size, s.sha256) == (size, sha256):
            return s  # resume
        if s is not None and not replace_session:
            raise UpdateRefused(ErrorCode.BUSY, f"an update of image {s.sha256.hex()[:16]} is in progress "
                                                f"({s.total_received} of {s.size} bytes); "
                                                "finish it or begin with REPLACE")
        if self.booted.mode == BootMode.TRIAL:
            raise UpdateRefused(ErrorCode.BAD_STATE, "the running image is on trial: confirm it (or reboot to revert) "
                                                     "before the next update")
        if not HEADER_LEN < size <= self.slots.layout.slot_size:
            raise UpdateRefused(ErrorCode.OUT_OF_RANGE, f"image of {size} bytes; a slot holds "
                                                        f"{self.slots.layout.slot_size}")
        state = self._state()
        slot = 1 - self.booted.slot if self.booted.slot is not None else 1 - state.active
        self.session = Session(slot, size, bytes(sha256))
        return self.session

    def data(self, offset: int, chunk: bytes) -> Session:
        s = self._need_session()
        if offset != s.total_received:
            raise UpdateRefused(ErrorCode.BAD_STATE, f"chunk at {offset}; the unit has {s.total_received} bytes, "
                                                     "continue there")
        if offset + len(chunk) > s.size:
            raise UpdateRefused(ErrorCode.OUT_OF_RANGE, f"chunk runs past the announced {s.size} bytes")
        before = s.total_received
        s.received += chunk
        if before < HEADER_LEN <= s.total_received:
            try:
                self._check_header(bytes(s.received[:HEADER_LEN]), s.size)
            except ImageError as exc:
                self.session = None
                raise UpdateRefused(ErrorCode.IMAGE_REJECTED, str(exc)) from exc
        return s

    def _check_header(self, head: bytes, size: int) -> None:
        payload_size, counter, _, target, kid, _ = parse_header(head)
        check_length(size, payload_size)
        if target != self.slots.target:
            raise ImageError(ImageFault.WRONG_TARGET, f"built for {target!r}, this unit is {self.slots.target!r}")
        if kid != key_id(self.slots.trusted):
            raise ImageError(ImageFault.WRONG_KEY, f"signed by key {kid.hex()}, the unit trusts "
                                                   f"{key_id(self.slots.trusted).hex()}")
        if counter < self._state().counter:
            raise ImageError(ImageFault.ROLLBACK, f"security counter {counter} is below the unit's "
                                                  f"{self._state().counter}")

    def _clear_trial(self, slot: int) -> None:
        """The target slot must not be pending when its bytes start to change."""
        state = self._state()
        if state.trial == slot:
            self.states.write(replace(state, trial=None, tried=False))

    def _program(self, slot: int, data: bytes) -> None:
        """Erase the slot's sectors and program ``data`` page by page."""
        page, sector = self.flash.page_size, self.flash.sector_size
        base = self.slots.layout.slot_addr(slot)
        for off in range(0, len(data), page):
            if (base + off) % sector == 0:
                self.flash.erase_sector(base + off)
            self.flash.program(base + off, data[off:off + page])

    def verify(self) -> tuple[int, FirmwareImage]:
        """Verify the received image, then (only then) write it to the slot and read it back."""
        s = self._need_session()
        if s.total_received != s.size:
            raise UpdateRefused(ErrorCode.BAD_STATE, f"{s.total_received} of {s.size} bytes received")
        data = bytes(s.received)
        if hashlib.sha256(data).digest() != s.sha256:
            self.session = None
            raise UpdateRefused(ErrorCode.IMAGE_REJECTED, "hash_mismatch: the unit did not receive the announced "
                                                          "image; begin again")
        try:
            self.slots.check(data, self._state().counter)
            self._clear_trial(s.slot)
            self._program(s.slot, data)
            if hashlib.sha256(self.slots.image_bytes(s.slot) or b"").digest() != s.sha256:
                raise UpdateRefused(ErrorCode.STORAGE, "the slot does not read back as the image written; begin again")
            s.verified = self.slots.verify(s.slot, self._state().counter)
        except ImageError as exc:
            self.session = None
            raise UpdateRefused(ErrorCode.IMAGE_REJECTED, str(exc)) from exc
        except UpdateRefused:
            self.session = None
            raise
        return s.slot, s.verified

    def activate(self) -> int:
        """Mark the verified image to boot in trial; the caller reboots the unit."""
        s = self._need_session()
        if s.verified is None:
            raise UpdateRefused(ErrorCode.BAD_STATE, "verify the image before activating it")
        self.states.write(replace(self._state(), trial=s.slot, tried=False))
        self.session = None
        return s.slot

    def confirm(self) -> int:
        """Make the running trial image the active one (idempotent for a confirmed image)."""
        b = self.booted
        if b.mode == BootMode.RECOVERY or b.slot is None or b.image is None:
            raise UpdateRefused(ErrorCode.BAD_STATE, "recovery runs no image to confirm")
        state = self._state()
        if b.mode == BootMode.TRIAL and state.trial == b.slot:
            self.states.write(BootState(b.slot, None, False, max(state.counter, b.image.security_counter)))
            self.booted = replace(b, mode=BootMode.NORMAL)
        return b.slot

    def _need_session(self) -> Session:
        if self.session is None:
            raise UpdateRefused(ErrorCode.BAD_STATE, "no update in progress; send UPDATE_BEGIN")
        return self.session

    # -- status ---------------------------------------------------------------------------------
    def slot_info(self, slot: int) -> SlotInfo:
        state, b = self._state(), self.booted
        try:
            image = self.slots.verify(slot, 0)
        except ImageError:
            empty = self.slots.image_bytes(slot) is None
            return SlotInfo(slot, SlotState.EMPTY if empty else SlotState.INVALID, 0, bytes(32), "")
        if b.mode == BootMode.TRIAL and b.slot == slot:
            kind = SlotState.TRIAL
        elif state.trial == slot and not state.tried:
            kind = SlotState.PENDING
        elif state.active == slot and image.security_counter >= state.counter:
            kind = SlotState.ACTIVE
        else:
            kind = SlotState.STANDBY
        return SlotInfo(slot, kind, image.security_counter, image.sha256, image.build.version)
