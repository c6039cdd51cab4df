"""The boot state: which slot is active, which one is on trial, the lowest security counter allowed.

Every change is one atomic record write, with the commit protocol of the calibration records
(calibration/store.py): two sectors written in turn, each record = magic "SBST", generation, body
length, body (JSON), CRC-32; the sector not holding the newest valid record is erased, every page
but the first programmed, then the first page (holding the magic) last. A cut at any step leaves
the previous record the newest valid one, so the unit always reads either the old or the new state.
"""
from __future__ import annotations

import json
import struct
import zlib
from dataclasses import asdict, dataclass

from .layout import FlashLayout

MAGIC = b"SBST"
_HEAD = struct.Struct("<4sII")  # magic, generation, body length
_CRC = struct.Struct("<I")


@dataclass(frozen=True)
class BootState:
    active: int = 0  # slot booted when no trial is pending (0 A, 1 B)
    trial: int | None = None  # slot activated for a trial boot
    tried: bool = False  # the trial boot has begun: the next boot reverts unless confirmed first
    counter: int = 0  # lowest security counter an image may carry
    generation: int = 0  # of the record read; 0: none stored

    def body(self) -> bytes:
        d = asdict(self)
        del d["generation"]
        return json.dumps(d, sort_keys=True).encode()


class BootStateStore:
    def __init__(self, layout: FlashLayout):
        self.layout = layout
        self.flash = layout.flash

    def _load(self, copy: int) -> BootState | None:
        addr = self.layout.state_addr(copy)
        magic, generation, length = _HEAD.unpack(self.flash.read(addr, _HEAD.size))
        if magic != MAGIC or not 0 < length <= self.flash.sector_size - _HEAD.size - _CRC.size:
            return None
        data = self.flash.read(addr, _HEAD.size + length + _CRC.size)
        if zlib.crc32(data[:-_CRC.size]) != _CRC.unpack(data[-_CRC.size:])[0]:
            return None
        try:
            d = json.loads(data[_HEAD.size:-_CRC.size])
            return BootState(int(d["active"]), d["trial"], bool(d["tried"]), int(d["counter"]), generation)
        except (ValueError, KeyError, TypeError):
            return None

    def _newest(self) -> tuple[BootState | None, int]:
        """The newest valid record and the copy it sits in (-1: none)."""
        found = [(s, c) for c, s in enumerate(self._load(c) for c in (0, 1)) if s is not None]
        if not found:
            return None, -1
        return max(found, key=lambda sc: sc[0].generation)

    def read(self) -> BootState | None:
        """The boot state in force, None on a unit never provisioned."""
        return self._newest()[0]

    def write(self, state: BootState) -> BootState:
        """Store ``state`` (power-loss safe); returns it with its new generation."""
        newest, copy = self._newest()
        generation = (newest.generation if newest else 0) + 1
        body = state.body()
        head = _HEAD.pack(MAGIC, generation, len(body)) + body
        record = head + _CRC.pack(zlib.crc32(head))
        addr = self.layout.state_addr(1 - copy if copy >= 0 else 0)
        page = self.flash.page_size
        self.flash.erase_sector(addr)
        if len(record) > page:
            self.flash.program_range(addr + page, record[page:])
        self.flash.program(addr, record[:page])  # commit
        return BootState(state.active, state.trial, state.tried, state.counter, generation)
