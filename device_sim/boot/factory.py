"""What the factory line does to a blank unit's flash: the trusted key into the locked security
register, the shipped image into slot A, the first boot state. Also the simulator's development
signing key (a fixed, public key pair, like MCUboot's sample keys: for simulated units only)."""
from __future__ import annotations

import hashlib

from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from stereocam.protocol.firmware_image import FirmwareBuild, build_image, parse_header

from ..calibration.flash import NorFlash
from .boot_state import BootState, BootStateStore
from .layout import FlashLayout

DEV_SIGNING_KEY = Ed25519PrivateKey.from_private_bytes(hashlib.sha256(b"stereocam simulator dev key").digest())
_KEY_TAG = b"SKEY"


def trusted_key(flash: NorFlash) -> Ed25519PublicKey | None:
    """The key provisioned in the security register, None on a blank unit."""
    otp = flash.otp_read()
    if otp[:4] != _KEY_TAG:
        return None
    return Ed25519PublicKey.from_public_bytes(otp[4:36])


def provision(layout: FlashLayout, vendor_key: Ed25519PrivateKey, build: FirmwareBuild, target: str) -> None:
    """Program a blank unit as the factory ships it (does nothing to a provisioned one)."""
    flash = layout.flash
    if trusted_key(flash) is None and not flash.otp_locked:
        raw = vendor_key.public_key().public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)
        flash.otp_program(_KEY_TAG + raw)
        flash.otp_lock()
    states = BootStateStore(layout)
    if states.read() is not None:
        return
    image = build_image(build, vendor_key, target=target)
    addr = layout.slot_addr(0)
    for sector in range(addr, addr + len(image), flash.sector_size):
        flash.erase_sector(sector)
    flash.program_range(addr, image)
    states.write(BootState(active=0, counter=parse_header(image)[1]))  # the shipped image is the floor
