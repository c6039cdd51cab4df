"""Where the boot stage keeps things on the unit's NOR flash, next to the calibration records.

    sectors 0..3          calibration records (calibration/store.py; 0..1 write-protected)
    sectors 4, 5          boot state records (boot_state.py), two copies written in turn
    slot A, slot B        the rest of the chip split in two equal image slots
    security register     the trusted firmware-signing key, locked at the factory (trust.py)
"""
from __future__ import annotations

from dataclasses import dataclass

from ..calibration.flash import NorFlash

FLASH_SIZE = 8 << 20  # a W25Q64-class part: two slots of ~4 MiB
BOOT_STATE_SECTOR = 4
FIRST_SLOT_SECTOR = 6
SLOT_NAMES = ("A", "B")


@dataclass(frozen=True)
class FlashLayout:
    flash: NorFlash

    @property
    def slot_size(self) -> int:
        sectors = (self.flash.size // self.flash.sector_size - FIRST_SLOT_SECTOR) // 2
        if sectors < 1:
            raise ValueError(f"a {self.flash.size}-byte flash has no room for two image slots")
        return sectors * self.flash.sector_size

    def slot_addr(self, slot: int) -> int:
        return FIRST_SLOT_SECTOR * self.flash.sector_size + slot * self.slot_size

    def state_addr(self, copy: int) -> int:
        return (BOOT_STATE_SECTOR + copy) * self.flash.sector_size
