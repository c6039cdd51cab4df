"""Power-loss-safe calibration record store on NOR flash.

Layout (sector = flash.sector_size, 4 KiB by default; the sectors: ../flash_map.py):
  factory region: slots F0, F1 (write-protected once locked); user region: slots U0, U1

Record, at offset 0 of a slot, all little-endian:
  offset      size  field
  0           4     magic, the bytes "SCAL" (u32 0x4C414353)
  4           2     format version (= 1)
  6           2     header length (= 16)
  8           4     body length n (1 .. sector - 20)
  12          4     generation (u32, 1 for the first record of a region, +1 per write)
  16          n     body (e.g. StereoCalibration.to_bytes())
  16+n        4     CRC-32 (zlib / IEEE 802.3) over bytes 0 .. 16+n-1
A slot is valid when magic, version, header length and body length are as above and the CRC
matches; an erased slot (magic 0xFFFFFFFF) or a tombstoned one (magic 0x00000000) is not.

Writing a region: pick the slot that does not hold the region's newest valid record (slot 0 if
none is valid), erase it, program every page of the new record except the first, then program
the first page (which holds the magic) last: that program is the commit. A cut before it leaves
the target slot without a magic (or, if torn, with a bad CRC), so the previous record is still the
newest valid one; the previous record's own slot is never touched.

restore_factory() tombstones the user slots by programming their magic to 0 (allowed on NOR
without an erase), the older slot first and the newest last, so a cut leaves either the old user
record or none (then the factory record is read).
"""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from typing import Literal

from stereocam.protocol.errors import StereoCamError

from ..flash_map import CALIBRATION_REGION_SECTOR, CALIBRATION_SECTORS
from .flash import NorFlash

MAGIC = 0x4C414353
FORMAT_VERSION = 1
_HEADER = struct.Struct("<IHHII")
_CRC = struct.Struct("<I")
_MAGIC_BYTES = struct.pack("<I", MAGIC)
_MAX_GENERATION = 0xFFFFFFFF

Region = Literal["factory", "user"]


class StoreError(StereoCamError):
    """A calibration store operation that cannot be done."""


class FactoryLockedError(StoreError):
    """write_factory on a store whose factory region is write-protected."""


@dataclass(frozen=True)
class StoredRecord:
    """A valid record read back from flash."""

    body: bytes
    generation: int
    region: Region
    slot: int


class CalibrationStore:
    """Factory and user calibration records on `flash` (see the module docstring)."""

    def __init__(self, flash: NorFlash) -> None:
        if flash.size < CALIBRATION_SECTORS * flash.sector_size:
            raise StoreError(f"the store needs {CALIBRATION_SECTORS} sectors, "
                             f"the flash has {flash.size // flash.sector_size}")
        self.flash = flash
        self.capacity = flash.sector_size - _HEADER.size - _CRC.size

    def _slot_addr(self, region: Region, slot: int) -> int:
        return (CALIBRATION_REGION_SECTOR[region] + slot) * self.flash.sector_size

    def _load(self, region: Region, slot: int) -> StoredRecord | None:
        addr = self._slot_addr(region, slot)
        magic, version, header_len, length, generation = _HEADER.unpack(self.flash.read(addr, _HEADER.size))
        if (magic, version, header_len) != (MAGIC, FORMAT_VERSION, _HEADER.size) or not 0 < length <= self.capacity:
            return None
        data = self.flash.read(addr, _HEADER.size + length + _CRC.size)
        (crc,) = _CRC.unpack_from(data, _HEADER.size + length)
        if zlib.crc32(data[:_HEADER.size + length]) != crc:
            return None
        return StoredRecord(data[_HEADER.size:_HEADER.size + length], generation, region, slot)

    def _highest_generation(self, region: Region) -> int:
        """The highest generation the region's slots hold, valid records and tombstones alike (a
        tombstone only zeroes the magic, its CRC checks with the magic put back): generations never
        repeat after a restore (SPEC §12.1). 0 when none."""
        best = 0
        for slot in (0, 1):
            addr = self._slot_addr(region, slot)
            magic, version, header_len, length, generation = _HEADER.unpack(self.flash.read(addr, _HEADER.size))
            if magic not in (MAGIC, 0) or (version, header_len) != (FORMAT_VERSION, _HEADER.size) \
                    or not 0 < length <= self.capacity:
                continue
            data = bytearray(self.flash.read(addr, _HEADER.size + length + _CRC.size))
            data[:4] = _MAGIC_BYTES
            (crc,) = _CRC.unpack_from(data, _HEADER.size + length)
            if zlib.crc32(data[:_HEADER.size + length]) == crc:
                best = max(best, generation)
        return best

    def _valid(self, region: Region) -> list[StoredRecord]:
        """The region's valid records, newest first (ties: lower slot first)."""
        recs = [r for r in (self._load(region, s) for s in (0, 1)) if r is not None]
        return sorted(recs, key=lambda r: (-r.generation, r.slot))

    def read(self) -> StoredRecord | None:
        """The newest valid user record, else the newest valid factory record, else None."""
        for region in ("user", "factory"):
            recs = self._valid(region)
            if recs:
                return recs[0]
        return None

    def read_factory(self) -> StoredRecord | None:
        """The newest valid factory record, or None."""
        recs = self._valid("factory")
        return recs[0] if recs else None

    def _write(self, region: Region, body: bytes) -> StoredRecord:
        if not 0 < len(body) <= self.capacity:
            raise StoreError(f"record body must be 1..{self.capacity} bytes, got {len(body)}")
        recs = self._valid(region)
        generation = self._highest_generation(region) + 1
        if generation > _MAX_GENERATION:
            raise StoreError(f"{region} generation counter exhausted")
        slot = 1 - recs[0].slot if recs else 0
        head = _HEADER.pack(MAGIC, FORMAT_VERSION, _HEADER.size, len(body), generation) + body
        record = head + _CRC.pack(zlib.crc32(head))
        addr = self._slot_addr(region, slot)
        page = self.flash.page_size
        self.flash.erase_sector(addr)
        if len(record) > page:
            self.flash.program_range(addr + page, record[page:])
        self.flash.program(addr, record[:page])  # commit: the page holding the magic
        return StoredRecord(bytes(body), generation, region, slot)

    def write_user(self, body: bytes) -> StoredRecord:
        """Store `body` as the new user record."""
        return self._write("user", body)

    def write_factory(self, body: bytes) -> StoredRecord:
        """Store `body` as the new factory record (FactoryLockedError once locked)."""
        if self.factory_locked:
            raise FactoryLockedError("the factory calibration region is write-protected")
        return self._write("factory", body)

    def restore_factory(self) -> None:
        """Invalidate every user record so that read() returns the factory record.

        Refused (StoreError, nothing touched) when there is no valid factory record.
        """
        if self.read_factory() is None:
            raise StoreError("no valid factory record to restore; user records left as they are")
        for rec in reversed(self._valid("user")):  # oldest first, newest last
            self.flash.program(self._slot_addr("user", rec.slot), b"\x00" * 4)

    @property
    def factory_locked(self) -> bool:
        """True when the flash's block protection covers the factory region."""
        return self.flash.protected_below >= self._slot_addr("user", 0)

    def lock_factory(self) -> None:
        """Write-protect the factory region (flash status register)."""
        self.flash.set_protection(self._slot_addr("user", 0))
