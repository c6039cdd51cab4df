"""What every message shares: the type table, the base classes, string fields (SPEC §4)."""
from __future__ import annotations

import enum
import struct
from dataclasses import dataclass
from typing import ClassVar


class MsgType(enum.IntEnum):
    GET_INFO = 0x0001
    GET_CONFIG = 0x0002
    SET_CONFIG = 0x0003
    TRIGGER = 0x0004
    START = 0x0005
    STOP = 0x0006
    HEARTBEAT = 0x0007
    TIME_SYNC = 0x0008
    CALIB_READ = 0x0009
    CALIB_WRITE = 0x000A
    CALIB_COMMIT = 0x000B
    CALIB_RESTORE = 0x000C
    SET_FRAME_LINK = 0x000D
    FRAME_RESEND = 0x000E
    UPDATE_BEGIN = 0x000F  # 1.2: firmware update (SPEC §14)
    UPDATE_DATA = 0x0010
    UPDATE_VERIFY = 0x0011
    UPDATE_ACTIVATE = 0x0012
    UPDATE_CONFIRM = 0x0013
    UPDATE_STATUS = 0x0014
    INFO = 0x8001
    CONFIG = 0x8002
    CONFIG_APPLIED = 0x8003
    TRIGGERED = 0x8004
    STARTED = 0x8005
    STOPPED = 0x8006
    STATUS = 0x8007
    TIME = 0x8008
    CALIB_DATA = 0x8009
    CALIB_WRITTEN = 0x800A
    CALIB_COMMITTED = 0x800B
    CALIB_RESTORED = 0x800C
    FRAME_LINK = 0x800D
    FRAME_RESENT = 0x800E
    UPDATE_BEGUN = 0x800F
    UPDATE_WRITTEN = 0x8010
    UPDATE_VERIFIED = 0x8011
    UPDATE_ACTIVATING = 0x8012
    UPDATE_CONFIRMED = 0x8013
    UPDATE_STATE = 0x8014
    FRAME_BEGIN = 0x4001
    FRAME_DATA = 0x4002
    FRAME_END = 0x4003
    NACK = 0xFFFF


REPLY_BIT = 0x8000
EVENT_BIT = 0x4000


def reply_type(request_type: int) -> int:
    return request_type | REPLY_BIT


def _str(s: str, width: str = "B") -> bytes:
    b = s.encode("utf-8")
    limit = (1 << (8 * struct.calcsize(width))) - 1
    b = b[:limit]
    return struct.pack("<" + width, len(b)) + b


def _read_str(payload: bytes, off: int, width: str = "B") -> tuple[str, int]:
    (n,) = struct.unpack_from("<" + width, payload, off)
    off += struct.calcsize(width)
    if off + n > len(payload):
        raise struct.error("string runs past the payload")
    return payload[off:off + n].decode("utf-8", errors="replace"), off + n


class Message:
    TYPE: ClassVar[int]

    def pack(self) -> bytes:
        return b""

    @classmethod
    def unpack(cls, payload: bytes) -> "Message":
        return cls()


@dataclass(frozen=True)
class _Empty(Message):
    pass
