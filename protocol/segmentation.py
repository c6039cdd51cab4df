"""How one capture becomes messages and back (SPEC §8.1–§8.2), shared by device and host.

The device turns a capture (its FRAME_BEGIN and the plane images) into the message sequence with
``capture_messages``; the host's assembler sizes and checks each plane with ``plane_size`` and
reads it with ``PLANE_DTYPE``.
"""
from __future__ import annotations

from collections.abc import Iterator, Mapping

import numpy as np

from .frame_messages import FRAME_DATA_HEAD, FRAME_OK, FrameBegin, FrameData, FrameEnd
from .framing import MAX_PAYLOAD
from .message_base import Message
from .params import Output
from .repair_messages import MAX_FRAME_CHUNK

PLANE_ORDER = (Output.LEFT, Output.RIGHT, Output.DISPARITY)  # the order planes are sent in
PLANE_DTYPE = {Output.LEFT: np.dtype(np.uint8), Output.RIGHT: np.dtype(np.uint8),
               Output.DISPARITY: np.dtype("<i2")}  # little-endian on the wire, row-major, no padding
REFERENCE_CHUNK = MAX_FRAME_CHUNK  # FRAME_DATA data bytes per message unless the host set another (§13.1)


def plane_size(plane: Output, width: int, height: int) -> int:
    """Bytes of one whole plane of a ``width`` × ``height`` capture."""
    return width * height * PLANE_DTYPE[plane].itemsize


def planes_of(begin: FrameBegin) -> list[Output]:
    """The planes a capture carries (FRAME_BEGIN ``planes``), in the order they are sent."""
    return [p for p in PLANE_ORDER if begin.planes & p]


def plane_bytes(begin: FrameBegin, images: Mapping[Output, np.ndarray], copy: bool = False
                ) -> dict[Output, memoryview]:
    """The wire bytes of every plane ``begin.planes`` names (``copy``: detached from ``images``).
    ValueError if a plane image is missing or does not have the capture's format."""
    raw: dict[Output, memoryview] = {}
    for plane in planes_of(begin):
        img = images.get(plane)
        if img is None or img.shape != (begin.height, begin.width):
            raise ValueError(f"plane {plane.name}: expected a {begin.height}x{begin.width} image, got "
                             f"{None if img is None else img.shape}")
        data = np.ascontiguousarray(img, dtype=PLANE_DTYPE[plane])
        raw[plane] = memoryview(data.tobytes() if copy else data).cast("B")
    return raw


def capture_messages(begin: FrameBegin, images: Mapping[Output, np.ndarray | memoryview],
                     chunk: int = REFERENCE_CHUNK) -> Iterator[Message]:
    """FRAME_BEGIN, then every plane of ``begin.planes`` as contiguous FRAME_DATA chunks of at most
    ``chunk`` data bytes, then FRAME_END with the bytes sent per plane. ``images`` are the plane
    images, or their bytes from ``plane_bytes``. ValueError if a plane is missing or the wrong size."""
    if not 0 < chunk <= MAX_PAYLOAD - FRAME_DATA_HEAD:
        raise ValueError(f"chunk of {chunk} bytes; must be 1..{MAX_PAYLOAD - FRAME_DATA_HEAD}")
    planes = planes_of(begin)
    if all(isinstance(images.get(p), memoryview) for p in planes):
        raw = {p: images[p] for p in planes}
        for p in planes:
            if len(raw[p]) != plane_size(p, begin.width, begin.height):
                raise ValueError(f"plane {p.name}: {len(raw[p])} bytes, expected "
                                 f"{plane_size(p, begin.width, begin.height)}")
    else:
        raw = plane_bytes(begin, images)
    yield begin
    for plane in planes:
        data = raw[plane]
        for off in range(0, len(data), chunk):
            yield FrameData(begin.sequence, int(plane), off, data[off:off + chunk])
    sent = {p: len(raw[p]) if p in raw else 0 for p in PLANE_ORDER}
    yield FrameEnd(begin.sequence, FRAME_OK, sent[Output.LEFT], sent[Output.RIGHT], sent[Output.DISPARITY])
