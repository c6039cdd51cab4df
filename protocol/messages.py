"""Typed messages of protocol v1 and their payload layouts (protocol/SPEC.md §4).

Each class has a ``TYPE``, ``pack() -> bytes`` and ``unpack(payload) -> message``. ``decode_packet``
turns a framing.Packet into its typed message; ``encode`` does the reverse. This module holds the
control messages and the registry; the shared base, the frame messages and the calibration
messages live in their own modules and are reachable from here (``m.FrameBegin``, ``m.CalibRead``).
"""
from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import ClassVar

from .calib_messages import (MAX_CALIB_CHUNK, CalibCommit, CalibCommitted, CalibData, CalibRead, CalibRestore,
                             CalibRestored, CalibSource, CalibState, CalibWrite, CalibWritten, calib_id)
from .errors import ProtocolError
from .frame_messages import (DISPARITY_S16_Q4, FRAME_OK, FRAME_RECTIFIED, FRAME_SENSOR_OVERRUN, FrameBegin,
                             FrameData, FrameEnd)
from .framing import Packet, encode_frame
from .repair_messages import (MAX_FRAME_CHUNK, MAX_RESEND_RANGES, MIN_FRAME_CHUNK, RESEND_GONE, RESEND_SENT,
                              FrameLink, FrameResend, FrameResent, SetFrameLink)
from .update_messages import (BEGIN_REPLACE, MAX_UPDATE_CHUNK, UPDATE_MESSAGES, UPDATE_REPLIES, BootMode, SlotInfo,
                              SlotReport, SlotState, UpdateActivate, UpdateActivating, UpdateBegin, UpdateBegun,
                              UpdateConfirm, UpdateConfirmed, UpdateData, UpdateProgress, UpdateState, UpdateStatus,
                              UpdateVerified, UpdateVerify, UpdateWritten)
from .message_base import EVENT_BIT, REPLY_BIT, Message, MsgType, _Empty, _read_str, _str, reply_type


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


class Capability:
    """INFO.capabilities bits (SPEC §4.1)."""

    DISPARITY = 0x01
    SOFTWARE_TRIGGER = 0x02
    EXTERNAL_TRIGGER = 0x04
    TIME_SYNC = 0x08
    CALIBRATION = 0x10  # since 1.1: CALIB_* messages (SPEC §12)
    RAW_OUTPUT = 0x20  # since 1.1: `rectify` = 0 gives raw (unrectified) frames (SPEC §5.1, §8.2)
    FRAME_REPAIR = 0x40  # since 1.2: SET_FRAME_LINK and FRAME_RESEND (SPEC §13)
    FIRMWARE_UPDATE = 0x80  # since 1.2: UPDATE_* messages (SPEC §14)
    TRIGGER_OUTPUT = 0x100  # since 1.2: `trigger_output` = 1 drives the trigger line (SPEC §5.1, §8.5)
    SGM = 0x200  # since 1.3: `algorithm` = 1, the semi-global matcher (SPEC §5.1); implied for a 1.2 device
    POST_PROCESSING = 0x400  # since 1.3: the post-processing parameters 30..39 (SPEC §5.1, §5.3)

    @classmethod
    def name_of(cls, bit: int) -> str:
        """The bit's name (``bit<n>`` for one this protocol version does not define)."""
        return next((k for k, v in vars(cls).items() if k.isupper() and v == bit), f"bit{bit.bit_length() - 1}")


def negotiated_capabilities(protocol_minor: int, capabilities: int) -> int:
    """What a device of ``protocol_minor`` advertising ``capabilities`` has (SPEC §11.2): a 1.2
    device implements SGM without the bit, which 1.3 added."""
    return capabilities | (Capability.SGM if protocol_minor == 2 else 0)


class Stage:
    """INFO stage limits' stage ids (SPEC §4.1): matching engines and later processing stages."""

    BLOCK_MATCHING = 1  # algorithm = 0
    SEMI_GLOBAL = 2  # algorithm = 1


_STAGE_LIMIT = struct.Struct("<HHH")


class UsbSpeed:
    """INFO.usb_speed (SPEC §4.1): the speed the unit's USB link enumerated at (libusb_speed values)."""

    NOT_USB = 0  # another link, or a device before 1.2
    HIGH = 3  # USB 2.0 high speed, 480 Mbit/s
    SUPER = 4  # USB 3.x super speed, 5 Gbit/s


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
    usb_speed: int = 0  # since 1.2: the USB link's speed (UsbSpeed), 0 = not on USB
    stage_limits: tuple[tuple[int, int, int], ...] = ()  # since 1.3: (Stage, max_width, max_height)

    def pack(self) -> bytes:
        head = self._S.pack(*self.protocol_version, self.capabilities, self.sensor_width, self.sensor_height,
                            self.max_payload, self.max_width, self.max_height)
        return head + _str(self.model) + _str(self.serial) + _str(self.firmware_version) + \
            struct.pack("<IBB", self.calibration_id, self.usb_speed, len(self.stage_limits)) + \
            b"".join(_STAGE_LIMIT.pack(*limit) for limit in self.stage_limits)

    @property
    def effective_capabilities(self) -> int:
        """The capabilities as negotiated (SPEC §11.2): the bits, plus what this minor implies."""
        return negotiated_capabilities(self.protocol_version[1], self.capabilities)

    def stage_limit(self, stage: int) -> tuple[int, int]:
        """(max_width, max_height) a stage supports: its entry, else the device's maxima (SPEC §4.1)."""
        for sid, w, h in self.stage_limits:
            if sid == stage:
                return min(w, self.max_width), min(h, self.max_height)
        return self.max_width, self.max_height

    @classmethod
    def unpack(cls, payload: bytes) -> "Info":
        major, minor, caps, sw, sh, mp, mw, mh = cls._S.unpack_from(payload, 0)
        off = cls._S.size
        model, off = _read_str(payload, off)
        serial, off = _read_str(payload, off)
        fw, off = _read_str(payload, off)
        cid = struct.unpack_from("<I", payload, off)[0] if len(payload) >= off + 4 else 0  # 1.0 devices
        speed = payload[off + 4] if len(payload) >= off + 5 else 0  # 1.0 and 1.1 devices
        off += 5
        n = payload[off] if len(payload) > off else 0  # before 1.3: no stage limits
        if n and len(payload) < off + 1 + n * _STAGE_LIMIT.size:
            raise struct.error(f"INFO announces {n} stage limits, the payload ends before them")
        limits = tuple(_STAGE_LIMIT.unpack_from(payload, off + 1 + k * _STAGE_LIMIT.size) for k in range(n))
        return cls(model, serial, fw, (major, minor), caps, sw, sh, mp, mw, mh, cid, speed, limits)


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
        return cls(dict(_param_pairs(payload)))


def _param_pairs(payload: bytes) -> tuple[tuple[int, int], ...]:
    """A param list's (id, value) entries in payload order (SPEC §4.2)."""
    (n,) = struct.unpack_from("<H", payload, 0)
    if len(payload) != 2 + n * _KV.size:
        raise struct.error(f"{n} parameters need {2 + n * _KV.size} bytes, got {len(payload)}")
    return tuple(_KV.iter_unpack(payload[2:]))


@dataclass(frozen=True)
class SetConfig(_ParamList):
    TYPE: ClassVar[int] = MsgType.SET_CONFIG
    entries: tuple[tuple[int, int], ...] = field(default=(), compare=False)
    """Every (id, value) in payload order when an id occurs more than once (``values`` keeps the last
    of each); empty otherwise. A device checks every entry (SPEC §4.3)."""

    @classmethod
    def unpack(cls, payload: bytes) -> "SetConfig":
        pairs = _param_pairs(payload)
        values = dict(pairs)
        return cls(values, pairs if len(pairs) != len(values) else ())

    @property
    def pairs(self) -> tuple[tuple[int, int], ...]:
        """The entries in payload order, duplicates included."""
        return self.entries or tuple(self.values.items())


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
    "rx_message_timeouts",  # since 1.2
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


CLOCK_DRIFT_TYPICAL = 50e-6  # a reference crystal's rate error (SPEC §10): the host's prior on drift
CLOCK_DRIFT_MAX = 1e-3  # the most a device clock may run fast or slow (SPEC §10); the host clamps here


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


_ALL: tuple[type[Message], ...] = (
    GetInfo, GetConfig, SetConfig, Trigger, Start, Stop, Heartbeat, TimeSync, Info, Config,
    ConfigApplied, Triggered, Started, Stopped, Status, Time, Nack, FrameBegin, FrameData, FrameEnd,
    CalibRead, CalibData, CalibWrite, CalibWritten, CalibCommit, CalibRestore, CalibCommitted, CalibRestored,
    SetFrameLink, FrameLink, FrameResend, FrameResent, *UPDATE_MESSAGES)
MESSAGES: dict[int, type[Message]] = {cls.TYPE: cls for cls in _ALL}

# request type -> reply class
REPLIES: dict[int, type[Message]] = {
    MsgType.GET_INFO: Info, MsgType.GET_CONFIG: Config, MsgType.SET_CONFIG: ConfigApplied,
    MsgType.TRIGGER: Triggered, MsgType.START: Started, MsgType.STOP: Stopped,
    MsgType.HEARTBEAT: Status, MsgType.TIME_SYNC: Time, MsgType.CALIB_READ: CalibData,
    MsgType.CALIB_WRITE: CalibWritten, MsgType.CALIB_COMMIT: CalibCommitted, MsgType.CALIB_RESTORE: CalibRestored,
    MsgType.SET_FRAME_LINK: FrameLink, MsgType.FRAME_RESEND: FrameResent,
    **UPDATE_REPLIES,
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


__all__ = [  # the whole message catalogue, whichever module defines each part
    "MsgType", "Message", "REPLY_BIT", "EVENT_BIT", "reply_type", "MESSAGES", "REPLIES", "decode_packet", "encode",
    "UnknownMessageError", "GetInfo", "GetConfig", "SetConfig", "Trigger", "Start", "Stop", "Heartbeat", "TimeSync",
    "Info", "Capability", "negotiated_capabilities", "Stage", "Config", "ConfigApplied", "Triggered", "Started",
    "Stopped", "Status", "COUNTERS", "Time", "Nack",
    "FrameBegin", "FrameData", "FrameEnd", "DISPARITY_S16_Q4", "FRAME_RECTIFIED", "FRAME_OK", "FRAME_SENSOR_OVERRUN",
    "CalibSource", "CalibRead", "CalibData", "CalibWrite", "CalibWritten", "CalibCommit", "CalibRestore",
    "CalibState", "CalibCommitted", "CalibRestored", "MAX_CALIB_CHUNK", "calib_id",
    "SetFrameLink", "FrameLink", "FrameResend", "FrameResent", "MIN_FRAME_CHUNK", "MAX_FRAME_CHUNK",
    "MAX_RESEND_RANGES", "RESEND_SENT", "RESEND_GONE",
    "UpdateBegin", "UpdateBegun", "UpdateData", "UpdateWritten", "UpdateProgress", "UpdateVerify", "UpdateVerified",
    "UpdateActivate", "UpdateActivating", "UpdateConfirm", "UpdateConfirmed", "UpdateStatus", "UpdateState",
    "SlotInfo", "SlotReport", "SlotState", "BootMode", "MAX_UPDATE_CHUNK", "BEGIN_REPLACE",
]
