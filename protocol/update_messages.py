"""Firmware update messages, protocol 1.2 (SPEC §14): begin, resumable data, verify, activate, confirm, status."""
from __future__ import annotations

import enum
import struct
from dataclasses import dataclass
from typing import ClassVar

from .message_base import Message, MsgType, _Empty, _read_str, _str

MAX_UPDATE_CHUNK = 60 * 1024  # image bytes one UPDATE_DATA SHOULD carry
BEGIN_REPLACE = 0x01  # UPDATE_BEGIN flag: abandon a transfer in progress of another image


class SlotState(enum.IntEnum):
    """What a slot holds, as UPDATE_STATE reports it."""

    EMPTY = 0  # erased: no image header
    ACTIVE = 1  # the confirmed image the unit boots
    PENDING = 2  # activated: boots in trial at the next boot
    TRIAL = 3  # running in trial, waiting for UPDATE_CONFIRM
    INVALID = 4  # holds bytes that fail verification (a partial transfer, a refused image)
    STANDBY = 5  # a valid image the unit does not boot (the previous one, a reverted trial, not yet activated)


class BootMode(enum.IntEnum):
    NORMAL = 0  # a confirmed image
    TRIAL = 1  # a new image on trial: reverts at the next boot unless confirmed
    RECOVERY = 2  # no valid image (or recovery requested): only INFO, HEARTBEAT and UPDATE_*


@dataclass(frozen=True)
class UpdateBegin(Message):
    """Start (or resume) the transfer of an image of ``size`` bytes whose SHA-256 is ``sha256``."""

    TYPE: ClassVar[int] = MsgType.UPDATE_BEGIN
    _S: ClassVar[struct.Struct] = struct.Struct("<I32sB")
    size: int
    sha256: bytes
    flags: int = 0

    def pack(self) -> bytes:
        return self._S.pack(self.size, self.sha256, self.flags)

    @classmethod
    def unpack(cls, payload: bytes) -> "UpdateBegin":
        return cls(*cls._S.unpack(payload))


@dataclass(frozen=True)
class UpdateData(Message):
    """Image bytes at ``offset``; the unit takes a chunk only where its received bytes end."""

    TYPE: ClassVar[int] = MsgType.UPDATE_DATA
    offset: int
    data: bytes

    def pack(self) -> bytes:
        return struct.pack("<I", self.offset) + self.data

    @classmethod
    def unpack(cls, payload: bytes) -> "UpdateData":
        return cls(struct.unpack_from("<I", payload)[0], bytes(payload[4:]))


@dataclass(frozen=True)
class UpdateProgress(Message):
    """Reply to BEGIN and DATA: the slot written and the contiguous bytes received of ``size``."""

    _S: ClassVar[struct.Struct] = struct.Struct("<BII")
    slot: int
    received: int
    size: int

    def pack(self) -> bytes:
        return self._S.pack(self.slot, self.received, self.size)

    @classmethod
    def unpack(cls, payload: bytes) -> "UpdateProgress":
        return cls(*cls._S.unpack(payload))


@dataclass(frozen=True)
class UpdateBegun(UpdateProgress):
    TYPE: ClassVar[int] = MsgType.UPDATE_BEGUN


@dataclass(frozen=True)
class UpdateWritten(UpdateProgress):
    TYPE: ClassVar[int] = MsgType.UPDATE_WRITTEN


@dataclass(frozen=True)
class UpdateVerify(_Empty):
    TYPE: ClassVar[int] = MsgType.UPDATE_VERIFY


@dataclass(frozen=True)
class UpdateActivate(_Empty):
    """Mark the verified image to boot in trial, then reboot (the link drops)."""

    TYPE: ClassVar[int] = MsgType.UPDATE_ACTIVATE


@dataclass(frozen=True)
class UpdateConfirm(_Empty):
    """Keep the image running in trial (after the host's health check)."""

    TYPE: ClassVar[int] = MsgType.UPDATE_CONFIRM


@dataclass(frozen=True)
class UpdateStatus(_Empty):
    TYPE: ClassVar[int] = MsgType.UPDATE_STATUS


@dataclass(frozen=True)
class SlotInfo:
    """One image slot as UPDATE_STATE and SlotReport carry it."""

    _S: ClassVar[struct.Struct] = struct.Struct("<BBI32s")
    slot: int
    state: int
    security_counter: int
    sha256: bytes
    version: str

    def pack(self) -> bytes:
        return self._S.pack(self.slot, self.state, self.security_counter, self.sha256) + _str(self.version)

    @classmethod
    def unpack_from(cls, payload: bytes, off: int) -> tuple["SlotInfo", int]:
        slot, state, counter, digest = cls._S.unpack_from(payload, off)
        version, off = _read_str(payload, off + cls._S.size)
        return cls(slot, state, counter, digest, version), off


@dataclass(frozen=True)
class SlotReport(Message):
    """Reply to VERIFY, ACTIVATE and CONFIRM: the slot concerned, its state after the request."""

    info: SlotInfo

    def pack(self) -> bytes:
        return self.info.pack()

    @classmethod
    def unpack(cls, payload: bytes) -> "SlotReport":
        info, off = SlotInfo.unpack_from(payload, 0)
        if off != len(payload):
            raise struct.error(f"{len(payload) - off} bytes after the slot")
        return cls(info)


@dataclass(frozen=True)
class UpdateVerified(SlotReport):
    TYPE: ClassVar[int] = MsgType.UPDATE_VERIFIED


@dataclass(frozen=True)
class UpdateActivating(SlotReport):
    TYPE: ClassVar[int] = MsgType.UPDATE_ACTIVATING


@dataclass(frozen=True)
class UpdateConfirmed(SlotReport):
    TYPE: ClassVar[int] = MsgType.UPDATE_CONFIRMED


@dataclass(frozen=True)
class UpdateState(Message):
    """Reply to UPDATE_STATUS: what runs, the transfer in progress, and every slot."""

    TYPE: ClassVar[int] = MsgType.UPDATE_STATE
    _S: ClassVar[struct.Struct] = struct.Struct("<BBII32sIB")
    running_slot: int  # 0 A, 1 B, 0xFF recovery
    boot_mode: int
    received: int  # transfer in progress: bytes received of ``size`` (size 0: none)
    size: int
    sha256: bytes
    security_counter: int  # the lowest counter the unit accepts
    slots: tuple[SlotInfo, ...]

    def pack(self) -> bytes:
        head = self._S.pack(self.running_slot, self.boot_mode, self.received, self.size, self.sha256,
                            self.security_counter, len(self.slots))
        return head + b"".join(s.pack() for s in self.slots)

    @classmethod
    def unpack(cls, payload: bytes) -> "UpdateState":
        running_slot, boot_mode, received, size, sha256, security_counter, n = cls._S.unpack_from(payload, 0)
        off, slots = cls._S.size, []
        for _ in range(n):
            slot, off = SlotInfo.unpack_from(payload, off)
            slots.append(slot)
        return cls(running_slot, boot_mode, received, size, sha256, security_counter, tuple(slots))


UPDATE_MESSAGES: tuple[type[Message], ...] = (
    UpdateBegin, UpdateBegun, UpdateData, UpdateWritten, UpdateVerify, UpdateVerified, UpdateActivate,
    UpdateActivating, UpdateConfirm, UpdateConfirmed, UpdateStatus, UpdateState)
UPDATE_REPLIES: dict[int, type[Message]] = {
    MsgType.UPDATE_BEGIN: UpdateBegun, MsgType.UPDATE_DATA: UpdateWritten, MsgType.UPDATE_VERIFY: UpdateVerified,
    MsgType.UPDATE_ACTIVATE: UpdateActivating, MsgType.UPDATE_CONFIRM: UpdateConfirmed,
    MsgType.UPDATE_STATUS: UpdateState}
