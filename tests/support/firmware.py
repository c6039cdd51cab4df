"""Firmware images and a unit's flash without the rest of the firmware: what the update tests share."""
from __future__ import annotations

import dataclasses
import hashlib
import shutil
from pathlib import Path

from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

from stereocam.device_sim.boot.boot_stage import Booted, BootStage
from stereocam.device_sim.boot.boot_state import BootStateStore
from stereocam.device_sim.boot.factory import DEV_SIGNING_KEY, provision, trusted_key
from stereocam.device_sim.boot.layout import FlashLayout
from stereocam.device_sim.boot.slots import Slots
from stereocam.device_sim.boot.update_service import UpdateService
from stereocam.device_sim.calibration.flash import NorFlash
from stereocam.device_sim.calibration.store import CalibrationStore
from stereocam.device_sim.calibration.truth import true_calibration
from stereocam.device_sim.handlers.device_info import FACTORY_BUILD, MODEL
from stereocam.protocol.firmware_image import FirmwareBuild, build_image

OTHER_KEY = Ed25519PrivateKey.from_private_bytes(bytes(range(32)))
SMALL_FLASH = 32 * 4096  # two slots of 13 sectors: room for the few-KiB images of the exhaustive tests
FACTORY_BODY = true_calibration(3).to_bytes()
USER_BODY = true_calibration(4).to_bytes()


def build(version: str, **defaults: int) -> FirmwareBuild:
    """The factory build with another version (and, optionally, other parameter defaults)."""
    return dataclasses.replace(FACTORY_BUILD, version=version,
                               parameter_defaults={**FACTORY_BUILD.parameter_defaults, **defaults})


def image(version: str, key: Ed25519PrivateKey | None = DEV_SIGNING_KEY, *, code_size: int = 0,
          counter: int | None = None, target: str = MODEL, **defaults: int) -> bytes:
    return build_image(build(version, **defaults), key, target=target, security_counter=counter,
                       code=bytes((i * 7) & 0xFF for i in range(code_size)))


def copy_flash(src: Path, dst: Path) -> None:
    """The flash file and its sidecars (status register, security register)."""
    for suffix in ("", ".sr", ".otp"):
        if Path(f"{src}{suffix}").exists():
            shutil.copyfile(f"{src}{suffix}", f"{dst}{suffix}")


class Unit:
    """A unit's flash (calibration + boot), its boot stage and update service, as after power-on."""

    def __init__(self, path: Path, size: int = SMALL_FLASH):
        self.path, self.size = path, size
        self.flash = NorFlash(path, size)
        self.layout = FlashLayout(self.flash)
        self.states = BootStateStore(self.layout)
        self.slots = Slots(self.layout, trusted_key(self.flash) or DEV_SIGNING_KEY.public_key(), MODEL)
        self.booted: Booted | None = None
        self.service: UpdateService | None = None

    @classmethod
    def factory(cls, path: Path, size: int = SMALL_FLASH) -> "Unit":
        """A blank unit through the factory line: calibrated (factory + user record), key, image A."""
        flash = NorFlash(path, size)
        store = CalibrationStore(flash)
        store.write_factory(FACTORY_BODY)
        store.lock_factory()
        store.write_user(USER_BODY)
        provision(FlashLayout(flash), DEV_SIGNING_KEY, FACTORY_BUILD, MODEL)
        return cls(path, size)

    def boot(self, recovery: bool = False) -> Booted:
        self.booted = BootStage(self.slots, self.states).boot(recovery)
        self.service = UpdateService(self.slots, self.states, self.booted)
        return self.booted

    def transfer(self, data: bytes, chunk: int = 1024) -> None:
        s = self.service.begin(len(data), hashlib.sha256(data).digest(), False)
        for off in range(s.total_received, len(data), chunk):
            self.service.data(off, data[off:off + chunk])
        self.service.verify()

    def calibration_intact(self) -> bool:
        store = CalibrationStore(self.flash)
        user, factory = store.read(), store.read_factory()
        return (user is not None and user.body == USER_BODY and factory is not None
                and factory.body == FACTORY_BODY and store.factory_locked)
