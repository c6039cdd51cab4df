"""Calibration storage messages, protocol 1.1 (SPEC §12)."""
from __future__ import annotations

import enum
import struct
import zlib
from dataclasses import dataclass
from typing import ClassVar

from .message_base import Message, MsgType, _Empty


MAX_CALIB_CHUNK = 60 * 1024  # data bytes per CALIB_DATA / CALIB_WRITE message


def calib_id(body: bytes) -> int:
    """A calibration record's id as frames carry it: CRC-32 of its body, never 0 (0 = uncalibrated)."""
    return zlib.crc32(body) or 1


class CalibSource(enum.IntEnum):
    """Which calibration record: in requests, what to read or write; in replies, what was found."""

    ACTIVE = 0  # request: the one in force (user if valid, else factory); reply: none found
    FACTORY = 1
    USER = 2


@dataclass(frozen=True)
class CalibRead(Message):
    """Read ``length`` bytes at ``offset`` of a stored calibration body (SPEC §12)."""

    TYPE: ClassVar[int] = MsgType.CALIB_READ
    _S: ClassVar[struct.Struct] = struct.Struct("<BII")
    source: int
    offset: int
    length: int

    def pack(self) -> bytes:
        return self._S.pack(self.source, self.offset, self.length)

    @classmethod
    def unpack(cls, payload: bytes) -> "CalibRead":
        return cls(*cls._S.unpack(payload))


@dataclass(frozen=True)
class CalibData(Message):
    TYPE: ClassVar[int] = MsgType.CALIB_DATA
    _S: ClassVar[struct.Struct] = struct.Struct("<BIIII")
    source: int  # CalibSource.ACTIVE (0) here means: no valid record
    generation: int
    calibration_id: int
    total: int  # body length
    offset: int
    data: bytes

    def pack(self) -> bytes:
        return self._S.pack(self.source, self.generation, self.calibration_id, self.total, self.offset) + self.data

    @classmethod
    def unpack(cls, payload: bytes) -> "CalibData":
        source, generation, calibration_id, total, offset = cls._S.unpack_from(payload, 0)
        return cls(source, generation, calibration_id, total, offset, bytes(payload[cls._S.size:]))


@dataclass(frozen=True)
class CalibWrite(Message):
    """Stage ``data`` at ``offset`` of a body of ``total`` bytes; offset 0 starts a new staging."""

    TYPE: ClassVar[int] = MsgType.CALIB_WRITE
    _S: ClassVar[struct.Struct] = struct.Struct("<II")
    offset: int
    total: int
    data: bytes

    def pack(self) -> bytes:
        return self._S.pack(self.offset, self.total) + self.data

    @classmethod
    def unpack(cls, payload: bytes) -> "CalibWrite":
        off, total = cls._S.unpack_from(payload, 0)
        return cls(off, total, bytes(payload[cls._S.size:]))


@dataclass(frozen=True)
class CalibWritten(Message):
    TYPE: ClassVar[int] = MsgType.CALIB_WRITTEN
    staged: int  # contiguous bytes staged so far

    def pack(self) -> bytes:
        return struct.pack("<I", self.staged)

    @classmethod
    def unpack(cls, payload: bytes) -> "CalibWritten":
        return cls(*struct.unpack("<I", payload))


@dataclass(frozen=True)
class CalibCommit(Message):
    """Write the staged body to flash as ``target`` (FACTORY or USER) if its CRC-32 is ``crc``."""

    TYPE: ClassVar[int] = MsgType.CALIB_COMMIT
    _S: ClassVar[struct.Struct] = struct.Struct("<BII")
    target: int
    total: int
    crc: int

    def pack(self) -> bytes:
        return self._S.pack(self.target, self.total, self.crc)

    @classmethod
    def unpack(cls, payload: bytes) -> "CalibCommit":
        return cls(*cls._S.unpack(payload))


@dataclass(frozen=True)
class CalibRestore(_Empty):
    """Invalidate the user calibration so the factory one is in force again."""

    TYPE: ClassVar[int] = MsgType.CALIB_RESTORE


@dataclass(frozen=True)
class CalibState(Message):
    """Reply to COMMIT and RESTORE: the calibration now in force."""

    _S: ClassVar[struct.Struct] = struct.Struct("<BII")
    source: int
    generation: int
    calibration_id: int

    def pack(self) -> bytes:
        return self._S.pack(self.source, self.generation, self.calibration_id)

    @classmethod
    def unpack(cls, payload: bytes) -> "CalibState":
        return cls(*cls._S.unpack(payload))


@dataclass(frozen=True)
class CalibCommitted(CalibState):
    TYPE: ClassVar[int] = MsgType.CALIB_COMMITTED


@dataclass(frozen=True)
class CalibRestored(CalibState):
    TYPE: ClassVar[int] = MsgType.CALIB_RESTORED
