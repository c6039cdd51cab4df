"""The unit's NOR flash map: which sectors each part of the firmware owns (one table for all of them).

    sectors 0, 1          calibration, factory region: slots F0, F1 (write-protected once locked)
    sectors 2, 3          calibration, user region: slots U0, U1 (calibration/store.py)
    sectors 4, 5          boot state records, two copies written in turn (boot/boot_state.py)
    sectors 6 ..          the rest of the chip split in two equal image slots A and B (boot/layout.py)
    security register     the trusted firmware-signing key, locked at the factory
"""
from __future__ import annotations

FLASH_SIZE = 8 << 20  # a W25Q64-class part: two image slots of ~4 MiB
CALIBRATION_REGION_SECTOR = {"factory": 0, "user": 2}  # first sector of each region; two slots each
CALIBRATION_SECTORS = 4  # sectors 0..3
BOOT_STATE_SECTOR = CALIBRATION_SECTORS  # two copies: 4, 5
FIRST_SLOT_SECTOR = BOOT_STATE_SECTOR + 2
