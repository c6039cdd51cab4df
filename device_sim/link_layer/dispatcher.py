"""Request → reply: the replay cache, the handler table, and the one place a refusal becomes a NACK."""
from __future__ import annotations

import collections
import logging
from collections.abc import Mapping
from typing import Any, Callable

from stereocam.protocol import messages as m
from stereocam.protocol.errors import ErrorCode, ProtocolError
from stereocam.protocol.framing import Packet

from .refusal import Refusal
from .replay_cache import ReplayCache

Handler = Callable[[Any], m.Message]
"""Each handler takes the message class of the type it is registered for (the table cannot say which)."""
log = logging.getLogger(__name__)


class Dispatcher:
    """Answers each request packet with exactly one encoded reply (SPEC §7)."""

    def __init__(self, counters: collections.Counter[str]):
        self.handlers: dict[int, Handler] = {}
        self.cache = ReplayCache()
        self._counters = counters

    def register(self, handlers: Mapping[int, Handler]) -> None:
        self.handlers.update(handlers)

    def answer(self, packet: Packet) -> bytes:
        """The reply's wire bytes: replayed for a RESEND already answered, else executed and cached."""
        replayed = self.cache.replay(packet)
        if replayed is not None:
            self._counters["resends_replayed"] += 1
            return replayed
        try:
            reply = self._execute(packet)
        except Refusal as exc:  # the state it guards is unchanged
            reply = self._nack(packet.msg_type, exc.code, exc.message, exc.param_id)
        except Exception as exc:  # a firmware bug still answers, so the host never just times out
            log.exception("handler for 0x%04x failed", packet.msg_type)
            reply = self._nack(packet.msg_type, ErrorCode.INTERNAL, f"{type(exc).__name__}: {exc}")
        wire = m.encode(reply, packet.request_id)
        self.cache.store(packet, wire)
        return wire

    def _execute(self, packet: Packet) -> m.Message:
        handler = self.handlers.get(packet.msg_type)
        if handler is None:
            raise Refusal(ErrorCode.UNKNOWN_TYPE, f"unknown request type 0x{packet.msg_type:04x}")
        try:
            msg = m.decode_packet(packet)
        except ProtocolError as exc:
            raise Refusal(ErrorCode.BAD_PAYLOAD, str(exc)) from exc
        return handler(msg)

    def _nack(self, request_type: int, code: ErrorCode, text: str, param_id: int = 0) -> m.Nack:
        self._counters["nacks"] += 1
        return m.Nack(request_type, code, param_id, text)
