"""Where the boot stage keeps its records and image slots on the unit's NOR flash (map: flash_map.py)."""
from __future__ import annotations

from dataclasses import dataclass

from ..calibration.flash import NorFlash
from ..flash_map import BOOT_STATE_SECTOR, FIRST_SLOT_SECTOR, FLASH_SIZE

__all__ = ["FLASH_SIZE", "SLOT_NAMES", "FlashLayout"]
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
