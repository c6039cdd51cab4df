"""Frame repair messages, protocol 1.2 (SPEC §13): the chunk size a link wants, and a selective
resend of the parts of a recent capture that arrived damaged or not at all."""
from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import ClassVar

from .message_base import Message, MsgType

MIN_FRAME_CHUNK = 256  # FRAME_DATA data bytes per message a device accepts in SET_FRAME_LINK
MAX_FRAME_CHUNK = 128 * 1024  # and the reference device's default (1.1 behaviour)
MAX_RESEND_RANGES = 255
RESEND_SENT = 0  # FRAME_RESENT.result: the ranges followed as FRAME_DATA, before this reply
RESEND_GONE = 1  # the capture is no longer kept (or never was): nothing sent


@dataclass(frozen=True)
class SetFrameLink(Message):
    """Host → device: FRAME_DATA chunk size for this link (0: the device's default)."""

    TYPE: ClassVar[int] = MsgType.SET_FRAME_LINK
    _S: ClassVar[struct.Struct] = struct.Struct("<I")
    chunk_size: int

    def pack(self) -> bytes:
        return self._S.pack(self.chunk_size)

    @classmethod
    def unpack(cls, payload: bytes) -> "SetFrameLink":
        return cls(*cls._S.unpack(payload))


@dataclass(frozen=True)
class FrameLink(Message):
    """The chunk size now in force and how many recent captures the device keeps for resends."""

    TYPE: ClassVar[int] = MsgType.FRAME_LINK
    _S: ClassVar[struct.Struct] = struct.Struct("<IH")
    chunk_size: int
    kept_captures: int

    def pack(self) -> bytes:
        return self._S.pack(self.chunk_size, self.kept_captures)

    @classmethod
    def unpack(cls, payload: bytes) -> "FrameLink":
        return cls(*cls._S.unpack(payload))


_RANGE = struct.Struct("<BII")


@dataclass(frozen=True)
class FrameResend(Message):
    """Host → device: send these byte ranges (plane, offset, length) of capture ``sequence`` again."""

    TYPE: ClassVar[int] = MsgType.FRAME_RESEND
    _S: ClassVar[struct.Struct] = struct.Struct("<IB")
    sequence: int
    ranges: tuple[tuple[int, int, int], ...] = ()

    def pack(self) -> bytes:
        if len(self.ranges) > MAX_RESEND_RANGES:
            raise ValueError(f"at most {MAX_RESEND_RANGES} ranges per FRAME_RESEND, got {len(self.ranges)}")
        return self._S.pack(self.sequence, len(self.ranges)) + b"".join(_RANGE.pack(*r) for r in self.ranges)

    @classmethod
    def unpack(cls, payload: bytes) -> "FrameResend":
        seq, n = cls._S.unpack_from(payload, 0)
        if len(payload) != cls._S.size + n * _RANGE.size:
            raise struct.error(f"{n} ranges need {cls._S.size + n * _RANGE.size} bytes, got {len(payload)}")
        return cls(seq, tuple(_RANGE.iter_unpack(payload[cls._S.size:])))


@dataclass(frozen=True)
class FrameResent(Message):
    """Reply, sent after the resent FRAME_DATA: ``result`` (RESEND_SENT / RESEND_GONE), the
    capture's FRAME_END status and the FRAME_DATA messages sent."""

    TYPE: ClassVar[int] = MsgType.FRAME_RESENT
    _S: ClassVar[struct.Struct] = struct.Struct("<IBBI")
    sequence: int
    result: int
    frame_status: int
    chunks: int

    def pack(self) -> bytes:
        return self._S.pack(self.sequence, self.result, self.frame_status, self.chunks)

    @classmethod
    def unpack(cls, payload: bytes) -> "FrameResent":
        return cls(*cls._S.unpack(payload))
