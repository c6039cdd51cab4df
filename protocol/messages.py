"""Typed messages of protocol v1 and their payload layouts (protocol/SPEC.md §4).

Each class has a ``TYPE``, ``pack() -> bytes`` and ``unpack(payload) -> message``. ``decode_packet``
turns a framing.Packet into its typed message; ``encode`` does the reverse.
"""
from __future__ import annotations

import enum
import struct
import zlib
from dataclasses import astuple, dataclass, field
from typing import ClassVar

from .errors import ProtocolError
from .framing import Packet, encode_frame


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


@dataclass(frozen=True)
class GetInfo(_Empty):
    TYPE: ClassVar[int] = MsgType.GET_INFO


@dataclass(frozen=True)
class GetConfig(_Empty):
    TYPE: ClassVar[int] = MsgType.GET_CONFIG


@dataclass(frozen=True)
class Trigger(_Empty):
    TYPE: ClassVar[int] = MsgType.TRIGGER


@dataclass(frozen=True)
class Start(_Empty):
    TYPE: ClassVar[int] = MsgType.START


@dataclass(frozen=True)
class Stop(_Empty):
    TYPE: ClassVar[int] = MsgType.STOP


@dataclass(frozen=True)
class Started(_Empty):
    TYPE: ClassVar[int] = MsgType.STARTED


@dataclass(frozen=True)
class Stopped(_Empty):
    TYPE: ClassVar[int] = MsgType.STOPPED


@dataclass(frozen=True)
class Heartbeat(_Empty):
    TYPE: ClassVar[int] = MsgType.HEARTBEAT


@dataclass(frozen=True)
class TimeSync(_Empty):
    TYPE: ClassVar[int] = MsgType.TIME_SYNC


@dataclass(frozen=True)
class Info(Message):
    TYPE: ClassVar[int] = MsgType.INFO
    _S: ClassVar[struct.Struct] = struct.Struct("<BBIHHIHH")
    model: str
    serial: str
    firmware_version: str
    protocol_version: tuple[int, int]
    capabilities: int
    sensor_width: int
    sensor_height: int
    max_payload: int
    max_width: int
    max_height: int
    calibration_id: int = 0  # since 1.1: the active calibration, 0 = uncalibrated

    def pack(self) -> bytes:
        head = self._S.pack(*self.protocol_version, self.capabilities, self.sensor_width, self.sensor_height,
                            self.max_payload, self.max_width, self.max_height)
        return head + _str(self.model) + _str(self.serial) + _str(self.firmware_version) + \
            struct.pack("<I", self.calibration_id)

    @classmethod
    def unpack(cls, payload: bytes) -> "Info":
        major, minor, caps, sw, sh, mp, mw, mh = cls._S.unpack_from(payload, 0)
        off = cls._S.size
        model, off = _read_str(payload, off)
        serial, off = _read_str(payload, off)
        fw, off = _read_str(payload, off)
        calib_id = struct.unpack_from("<I", payload, off)[0] if len(payload) >= off + 4 else 0  # 1.0 devices
        return cls(model, serial, fw, (major, minor), caps, sw, sh, mp, mw, mh, calib_id)


_KV = struct.Struct("<Hi")


@dataclass(frozen=True)
class _ParamList(Message):
    values: dict[int, int] = field(default_factory=dict)  # wire id -> int32

    def pack(self) -> bytes:
        parts = [struct.pack("<H", len(self.values))]
        parts += [_KV.pack(k, v) for k, v in self.values.items()]
        return b"".join(parts)

    @classmethod
    def unpack(cls, payload: bytes) -> "_ParamList":
        (n,) = struct.unpack_from("<H", payload, 0)
        if len(payload) != 2 + n * _KV.size:
            raise struct.error(f"{n} parameters need {2 + n * _KV.size} bytes, got {len(payload)}")
        return cls({k: v for k, v in _KV.iter_unpack(payload[2:])})


@dataclass(frozen=True)
class SetConfig(_ParamList):
    TYPE: ClassVar[int] = MsgType.SET_CONFIG


@dataclass(frozen=True)
class Config(_ParamList):
    TYPE: ClassVar[int] = MsgType.CONFIG


@dataclass(frozen=True)
class ConfigApplied(_ParamList):
    TYPE: ClassVar[int] = MsgType.CONFIG_APPLIED


@dataclass(frozen=True)
class Triggered(Message):
    TYPE: ClassVar[int] = MsgType.TRIGGERED
    _S: ClassVar[struct.Struct] = struct.Struct("<II")
    trigger_id: int
    sequence: int

    def pack(self) -> bytes:
        return self._S.pack(self.trigger_id, self.sequence)

    @classmethod
    def unpack(cls, payload: bytes) -> "Triggered":
        return cls(*cls._S.unpack(payload))


COUNTERS: tuple[str, ...] = (
    "frames_captured", "frames_sent", "frames_dropped", "triggers", "rx_bytes", "rx_packets",
    "rx_garbage_bytes", "rx_header_crc_errors", "rx_payload_crc_errors", "rx_oversize",
    "rx_unsupported_version", "nacks", "resends_replayed", "heartbeat_timeouts",
)


@dataclass(frozen=True)
class Status(Message):
    """Heartbeat reply: uptime, state and every device counter (SPEC §4.7)."""

    TYPE: ClassVar[int] = MsgType.STATUS
    _S: ClassVar[struct.Struct] = struct.Struct("<QBBH")
    uptime_us: int
    streaming: bool
    trigger_mode: int
    counters: dict[str, int]

    def pack(self) -> bytes:
        vals = [self.counters.get(name, 0) for name in COUNTERS]
        return self._S.pack(self.uptime_us, int(self.streaming), self.trigger_mode, len(vals)) + \
            struct.pack(f"<{len(vals)}Q", *vals)

    @classmethod
    def unpack(cls, payload: bytes) -> "Status":
        up, streaming, mode, n = cls._S.unpack_from(payload, 0)
        vals = struct.unpack_from(f"<{n}Q", payload, cls._S.size)
        names = COUNTERS + tuple(f"counter_{i}" for i in range(len(COUNTERS), n))
        return cls(up, bool(streaming), mode, dict(zip(names, vals)))


@dataclass(frozen=True)
class Time(Message):
    TYPE: ClassVar[int] = MsgType.TIME
    device_time_us: int

    def pack(self) -> bytes:
        return struct.pack("<Q", self.device_time_us)

    @classmethod
    def unpack(cls, payload: bytes) -> "Time":
        return cls(*struct.unpack("<Q", payload))


@dataclass(frozen=True)
class Nack(Message):
    TYPE: ClassVar[int] = MsgType.NACK
    _S: ClassVar[struct.Struct] = struct.Struct("<HHH")
    request_type: int
    code: int
    param_id: int  # 0: no parameter involved
    message: str

    def pack(self) -> bytes:
        return self._S.pack(self.request_type, self.code, self.param_id) + _str(self.message, "H")

    @classmethod
    def unpack(cls, payload: bytes) -> "Nack":
        rt, code, pid = cls._S.unpack_from(payload, 0)
        text, _ = _read_str(payload, cls._S.size, "H")
        return cls(rt, code, pid, text)


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
        head = cls._S.unpack_from(payload, 0)
        return cls(*head, bytes(payload[cls._S.size:]))


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


DISPARITY_S16_Q4 = 1  # int16 little-endian, value = disparity * subpixel
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
    """Trailer: device status and the bytes sent per plane (left, right, disparity)."""

    TYPE: ClassVar[int] = MsgType.FRAME_END
    _S: ClassVar[struct.Struct] = struct.Struct("<IBIII")
    sequence: int
    status: int
    left_bytes: int
    right_bytes: int
    disparity_bytes: int

    def pack(self) -> bytes:
        return self._S.pack(self.sequence, self.status, self.left_bytes, self.right_bytes, self.disparity_bytes)

    @classmethod
    def unpack(cls, payload: bytes) -> "FrameEnd":
        return cls(*cls._S.unpack(payload))


MESSAGES: dict[int, type[Message]] = {
    cls.TYPE: cls for cls in (
        GetInfo, GetConfig, SetConfig, Trigger, Start, Stop, Heartbeat, TimeSync, Info, Config,
        ConfigApplied, Triggered, Started, Stopped, Status, Time, Nack, FrameBegin, FrameData, FrameEnd,
        CalibRead, CalibData, CalibWrite, CalibWritten, CalibCommit, CalibRestore, CalibCommitted, CalibRestored)
}

# request type -> reply class
REPLIES: dict[int, type[Message]] = {
    MsgType.GET_INFO: Info, MsgType.GET_CONFIG: Config, MsgType.SET_CONFIG: ConfigApplied,
    MsgType.TRIGGER: Triggered, MsgType.START: Started, MsgType.STOP: Stopped,
    MsgType.HEARTBEAT: Status, MsgType.TIME_SYNC: Time, MsgType.CALIB_READ: CalibData,
    MsgType.CALIB_WRITE: CalibWritten, MsgType.CALIB_COMMIT: CalibCommitted, MsgType.CALIB_RESTORE: CalibRestored,
}


class UnknownMessageError(ProtocolError):
    """A frame of a type this code does not know."""


def decode_packet(packet: Packet) -> Message:
    """The typed message a packet carries; ProtocolError naming the type if it is malformed."""
    cls = MESSAGES.get(packet.msg_type)
    if cls is None:
        raise UnknownMessageError(f"unknown message type 0x{packet.msg_type:04x}")
    if issubclass(cls, _Empty):
        if packet.payload:
            raise ProtocolError(f"{cls.__name__} takes no payload, got {len(packet.payload)} bytes")
        return cls()
    try:
        return cls.unpack(packet.payload)
    except (struct.error, ValueError, UnicodeDecodeError) as exc:
        raise ProtocolError(f"malformed {cls.__name__} payload ({len(packet.payload)} bytes): {exc}") from exc


def encode(msg: Message, request_id: int = 0, flags: int = 0) -> bytes:
    """A message as one frame on the wire."""
    return encode_frame(msg.TYPE, request_id, msg.pack(), flags)
