"""Signed firmware images: what verifies, and the fault named for each kind of bad image."""
from __future__ import annotations

import pytest

from stereocam.device_sim.boot.factory import DEV_SIGNING_KEY
from stereocam.protocol.firmware_image import (HEADER_LEN, FirmwareBuild, ImageError, ImageFault,
                                               auto_security_counter, inspect_image, load_private_key,
                                               private_key_pem, verify_image)
from tests.support.firmware import OTHER_KEY, image

TRUSTED = DEV_SIGNING_KEY.public_key()


def test_a_signed_image_verifies_and_carries_its_build() -> None:
    data = image("1.4.2", code_size=1000, fps=12)
    img = verify_image(data, TRUSTED, "STOC-SIM")
    assert img.version == (1, 4, 2) and img.build.version == "1.4.2" and img.build.parameter_defaults["fps"] == 12
    assert img.security_counter == auto_security_counter("1.4.2") and img.code_size == 1000 and img.size == len(data)
    assert inspect_image(data) == img


def _bad(data: bytes, min_counter: int = 0) -> ImageFault:
    with pytest.raises(ImageError) as info:
        verify_image(data, TRUSTED, "STOC-SIM", min_counter)
    assert str(info.value).startswith(info.value.fault.name.lower())
    return info.value.fault


def test_each_bad_image_is_refused_with_its_reason() -> None:
    good = image("1.2.0", code_size=500)
    assert _bad(image("1.2.0", key=None, code_size=500)) == ImageFault.UNSIGNED
    assert _bad(good[:-1]) == ImageFault.TRUNCATED
    assert _bad(good[:HEADER_LEN - 1]) == ImageFault.TRUNCATED
    assert _bad(good + b"\0") == ImageFault.MALFORMED
    assert _bad(b"XXXX" + good[4:]) == ImageFault.MALFORMED
    flipped = bytearray(good)
    flipped[HEADER_LEN + 300] ^= 1  # a code byte
    assert _bad(bytes(flipped)) == ImageFault.TAMPERED
    flipped = bytearray(good)
    flipped[12] ^= 1  # the security counter, in the signed header
    assert _bad(bytes(flipped)) == ImageFault.TAMPERED
    flipped = bytearray(good)
    flipped[-1] ^= 1  # the signature
    assert _bad(bytes(flipped)) == ImageFault.TAMPERED
    assert _bad(image("1.2.0", key=OTHER_KEY)) == ImageFault.WRONG_KEY
    assert _bad(image("1.2.0", target="STOC-PRO")) == ImageFault.WRONG_TARGET
    assert _bad(good, min_counter=auto_security_counter("1.3.0")) == ImageFault.ROLLBACK
    assert verify_image(image("1.0.0", counter=auto_security_counter("1.3.0")), TRUSTED, "STOC-SIM",
                        auto_security_counter("1.3.0")).build.version == "1.0.0"  # a signed rollback image


def test_builds_and_keys_reject_garbage() -> None:
    with pytest.raises(ImageError, match="version"):
        FirmwareBuild.from_json(b'{"version": "one", "protocol_minor": 2, "capabilities": 1}')
    with pytest.raises(ImageError, match="not a firmware build"):
        FirmwareBuild.from_json(b"[]")
    assert load_private_key(private_key_pem(OTHER_KEY)).public_key() == OTHER_KEY.public_key()
    with pytest.raises(ImageError, match="PEM"):
        load_private_key(b"not a key")
