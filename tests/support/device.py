"""What device tests share: the small format they run at, and the URL of each transport's device."""
from __future__ import annotations

import pytest

SMALL = {"width": 320, "height": 240, "num_disparities": 32, "block_size": 11}
"""A small format so device tests run fast."""


def url_of(kind: str, request: pytest.FixtureRequest) -> str:
    """The URL of the device test's transport ``kind`` (starting its simulator), or --device's URL."""
    if kind == "sim":
        return "sim://?seed=7"
    if kind == "usb":
        return request.getfixturevalue("usb_camera")
    if kind in ("pty", "tcp"):
        return request.getfixturevalue("served")(kind).url
    return kind  # an external device URL from --device
