"""Reading the image slots: what each holds and whether it may run."""
from __future__ import annotations

from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

from stereocam.protocol.firmware_image import (HEADER_LEN, SIGNATURE_LEN, FirmwareImage, ImageError, ImageFault,
                                               parse_header, verify_image)

from ..calibration.flash import NorFlash
from .layout import FlashLayout


class Slots:
    """The two image slots, checked against the unit's trusted key and target (model)."""

    def __init__(self, layout: FlashLayout, trusted: Ed25519PublicKey, target: str):
        self.layout = layout
        self.flash: NorFlash = layout.flash
        self.trusted = trusted
        self.target = target

    def image_bytes(self, slot: int) -> bytes | None:
        """The slot's image as its header sizes it (None: erased or no header)."""
        addr = self.layout.slot_addr(slot)
        head = self.flash.read(addr, HEADER_LEN)
        if head == b"\xff" * HEADER_LEN:
            return None
        try:
            size = parse_header(head)[0]
        except ImageError:
            return head
        total = min(HEADER_LEN + size + SIGNATURE_LEN, self.layout.slot_size)
        return self.flash.read(addr, total)

    def check(self, data: bytes, min_counter: int) -> FirmwareImage:
        """``data`` parsed if it may run on this unit; ImageError if not."""
        return verify_image(data, self.trusted, self.target, min_counter)

    def verify(self, slot: int, min_counter: int) -> FirmwareImage:
        """The slot's image if it may run; ImageError (MALFORMED for an empty slot) if not."""
        data = self.image_bytes(slot)
        if data is None:
            raise ImageError(ImageFault.MALFORMED, f"slot {'AB'[slot]} is empty")
        return self.check(data, min_counter)
