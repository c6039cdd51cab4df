"""Signed firmware images: what verifies, and the fault named for each kind of bad image."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from stereocam.device_sim.boot.factory import DEV_SIGNING_KEY
from stereocam.device_sim.boot.update_service import UpdateRefused
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.firmware_image import (HEADER_LEN, FirmwareBuild, ImageError, ImageFault,
                                               auto_security_counter, build_image, inspect_image,
                                               load_private_key, private_key_pem, verify_image)
from tests.support.firmware import OTHER_KEY, Unit, build, image

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


_GOOD_BUILD = {"version": "1.2.0", "protocol_minor": 2, "capabilities": 7, "parameter_defaults": {"fps": 12}}


@pytest.mark.parametrize("change, field", [
    ({"protocol_minor": 99999999999}, "protocol_minor"), ({"protocol_minor": 256}, "protocol_minor"),
    ({"protocol_minor": -1}, "protocol_minor"), ({"protocol_minor": True}, "protocol_minor"),
    ({"protocol_minor": 2.5}, "protocol_minor"), ({"capabilities": -5}, "capabilities"),
    ({"capabilities": 2**32}, "capabilities"), ({"capabilities": "7"}, "capabilities"),
    ({"parameter_defaults": {"fps": 1000}}, "fps"), ({"parameter_defaults": {"fps": 2**31}}, "fps"),
    ({"parameter_defaults": {"future_param": -2**31 - 1}}, "future_param"),
    ({"parameter_defaults": {"gain": None}}, "gain"), ({"parameter_defaults": [1, 2]}, "parameter_defaults"),
    ({"version": " 1.2.0"}, "version"), ({"version": "1_0.2.0"}, "version"), ({"version": 1.2}, "version"),
    ({"version": "1.2.0+" + "x" * 300}, "version"), ({"version": "1.2.0+\ud800"}, "version")])
def test_a_build_a_unit_could_not_report_or_apply_is_malformed_naming_the_field(change: dict, field: str) -> None:
    data = json.dumps({**_GOOD_BUILD, **change}).encode()
    with pytest.raises(ImageError) as info:
        FirmwareBuild.from_json(data)
    assert info.value.fault == ImageFault.MALFORMED and field in str(info.value)


@pytest.mark.parametrize("text, field", [
    ('"capabilities": 1e400', "capabilities"), ('"capabilities": -1e400', "capabilities"),
    ('"capabilities": NaN', "capabilities"), ('"protocol_minor": 1e400', "protocol_minor"),
    ('"parameter_defaults": {"fps": 1e400}', "fps")])
def test_infinite_numbers_in_a_build_are_malformed_not_an_overflow(text: str, field: str) -> None:
    fields = {"version": '"1.2.0"', "protocol_minor": "2", "capabilities": "7", "parameter_defaults": "{}"}
    name, value = text.split(": ", 1)
    fields[name.strip('"')] = value
    data = ("{" + ", ".join(f'"{k}": {v}' for k, v in fields.items()) + "}").encode()
    with pytest.raises(ImageError) as info:
        FirmwareBuild.from_json(data)
    assert info.value.fault == ImageFault.MALFORMED and field in str(info.value)


def test_a_build_at_the_edges_of_its_ranges_is_accepted() -> None:
    edge = {"version": "255.255.65535+build.7", "protocol_minor": 255, "capabilities": 2**32 - 1,
            "parameter_defaults": {"fps": 120, "future_param": -2**31}}
    build = FirmwareBuild.from_json(json.dumps(edge).encode())
    assert (build.protocol_minor, build.capabilities, build.parameter_defaults["future_param"]) == (255, 2**32 - 1,
                                                                                                   -2**31)


@pytest.mark.parametrize("kwargs, words", [
    ({"counter": -1}, "security counter"), ({"counter": 2**32}, "security counter"),
    ({"counter": 99999999999999}, "security counter"), ({"target": "ABCDEFGHIJKLMNOPQ"}, "at most 16"),
    ({"target": "ABCDEFGHIJKLMNOé"}, "ASCII"), ({"target": ""}, "target")])
def test_build_image_refuses_header_fields_it_cannot_hold(kwargs: dict, words: str) -> None:
    with pytest.raises(ImageError, match=words) as info:
        image("1.2.0", **kwargs)
    assert info.value.fault == ImageFault.MALFORMED


def test_header_fields_at_their_limits_round_trip() -> None:
    data = image("1.2.0", counter=2**32 - 1, target="ABCDEFGHIJKLMNOP")
    img = verify_image(data, TRUSTED, "ABCDEFGHIJKLMNOP")
    assert (img.security_counter, img.target) == (2**32 - 1, "ABCDEFGHIJKLMNOP")


@pytest.mark.parametrize("bad", [
    dataclasses.replace(build("1.2.0"), protocol_minor=99999999999),
    dataclasses.replace(build("1.2.0"), capabilities=-5),
    build("1.2.0", fps=10**12)])
def test_a_unit_refuses_a_signed_image_whose_build_is_out_of_range(tmp_path: Path, bad: FirmwareBuild) -> None:
    unit = Unit.factory(tmp_path / "unit.flash")
    unit.boot()
    state = unit.states.read()
    data = build_image(bad, DEV_SIGNING_KEY, target="STOC-SIM")  # signed as is: a signer that did not check
    with pytest.raises(UpdateRefused, match="^malformed: ") as refused:
        unit.transfer(data)
    assert refused.value.code == ErrorCode.IMAGE_REJECTED
    assert unit.states.read() == state  # no slot was made pending
    with pytest.raises(UpdateRefused, match="no update in progress"):
        unit.service.activate()
    assert unit.boot().slot == 0 and unit.booted.image.build.version == "1.1.0"
