"""How a capture travels: FRAME_BEGIN leader, FRAME_DATA chunks, FRAME_END trailer (SPEC §8)."""
from __future__ import annotations

import struct
from dataclasses import astuple, dataclass
from typing import ClassVar

from .message_base import Message, MsgType


DISPARITY_S16_Q4 = 1  # int16 little-endian, value = disparity * subpixel
DISPARITY_SUBPIXEL = 16  # the subpixel factor of DISPARITY_S16_Q4 (4 fraction bits)
# The CONFIDENCE plane (since 1.3, SPEC §5.3), uint8 per pixel: 0 where the disparity plane is
# invalid, CONFIDENCE_FILLED where only hole filling gave it a value, else CONFIDENCE_BASE +
# CONFIDENCE_PER_NEIGHBOUR * n with n the 8-neighbours whose matched disparity is within 1 px (255 at 8).
CONFIDENCE_FILLED = 16
CONFIDENCE_BASE = 31
CONFIDENCE_PER_NEIGHBOUR = 28


def invalid_disparity(min_disparity: int) -> int:
    """The code a DISPARITY_S16_Q4 plane holds where no disparity was found: one step below the
    search range, (min_disparity - 1) * 16 (SPEC §4.9)."""
    return (min_disparity - 1) * DISPARITY_SUBPIXEL
FRAME_RECTIFIED = 0x01  # frame flags


@dataclass(frozen=True)
class FrameBegin(Message):
    """Leader of one capture: metadata and the disparity's self-description (SPEC §4.9)."""

    TYPE: ClassVar[int] = MsgType.FRAME_BEGIN
    _S: ClassVar[struct.Struct] = struct.Struct("<IIQIHHHBBBBhHhIffff")
    sequence: int
    trigger_id: int
    device_time_us: int
    exposure_us: int
    gain: int
    width: int
    height: int
    planes: int
    flags: int
    disparity_format: int
    subpixel: int
    min_disparity: int
    num_disparities: int
    invalid_disparity: int
    calibration_id: int
    focal_px: float
    cx: float
    cy: float
    baseline_m: float

    def pack(self) -> bytes:
        return self._S.pack(*astuple(self))

    @classmethod
    def unpack(cls, payload: bytes) -> "FrameBegin":
        return cls(*cls._S.unpack(payload))


_FD = struct.Struct("<IBI")
FRAME_DATA_HEAD = _FD.size  # payload bytes before the data: sequence, plane, offset


@dataclass(frozen=True)
class FrameData(Message):
    """A chunk of one plane of one capture, at a byte offset into that plane."""

    TYPE: ClassVar[int] = MsgType.FRAME_DATA
    sequence: int
    plane: int
    offset: int
    data: bytes | memoryview

    def pack(self) -> bytes:
        return _FD.pack(self.sequence, self.plane, self.offset) + self.data

    @classmethod
    def unpack(cls, payload: bytes) -> "FrameData":
        seq, plane, off = _FD.unpack_from(payload, 0)
        return cls(seq, plane, off, memoryview(payload)[_FD.size:])


FRAME_OK = 0
FRAME_SENSOR_OVERRUN = 1  # device status: the capture was cut short on the device


@dataclass(frozen=True)
class FrameEnd(Message):
    """Trailer: device status and the bytes sent per plane (left, right, disparity; since 1.3 the
    confidence plane's, a trailing u32 present only when that plane was sent)."""

    TYPE: ClassVar[int] = MsgType.FRAME_END
    _S: ClassVar[struct.Struct] = struct.Struct("<IBIII")
    _CONFIDENCE: ClassVar[struct.Struct] = struct.Struct("<I")
    sequence: int
    status: int
    left_bytes: int
    right_bytes: int
    disparity_bytes: int
    confidence_bytes: int = 0

    def pack(self) -> bytes:
        head = self._S.pack(self.sequence, self.status, self.left_bytes, self.right_bytes, self.disparity_bytes)
        return head + self._CONFIDENCE.pack(self.confidence_bytes) if self.confidence_bytes else head

    @classmethod
    def unpack(cls, payload: bytes) -> "FrameEnd":
        if len(payload) == cls._S.size + cls._CONFIDENCE.size:
            return cls(*cls._S.unpack_from(payload), *cls._CONFIDENCE.unpack_from(payload, cls._S.size))
        return cls(*cls._S.unpack(payload))
