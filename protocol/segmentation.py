"""How one capture becomes messages and back (SPEC §8.1–§8.2), shared by device and host.

The device turns a capture (its FRAME_BEGIN and the plane images) into the message sequence with
``capture_messages``; the host's assembler sizes and checks each plane with ``plane_size`` and
reads it with ``PLANE_DTYPE``.
"""
from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from typing import Union

import numpy as np

from .frame_messages import FRAME_DATA_HEAD, FRAME_OK, FrameBegin, FrameData, FrameEnd
from .framing import MAX_PAYLOAD
from .message_base import Message
from .params import Output
from .repair_messages import MAX_FRAME_CHUNK

PLANE_ORDER = (Output.LEFT, Output.RIGHT, Output.DISPARITY, Output.CONFIDENCE)  # the order planes are sent in
PLANE_DTYPE: dict[int, np.dtype] = {Output.LEFT: np.dtype(np.uint8), Output.RIGHT: np.dtype(np.uint8),
               Output.DISPARITY: np.dtype("<i2"), Output.CONFIDENCE: np.dtype(np.uint8)}
"""Little-endian on the wire, row-major, no padding."""
REFERENCE_CHUNK = MAX_FRAME_CHUNK  # FRAME_DATA data bytes per message unless the host set another (§13.1)


def plane_size(plane: Output, width: int, height: int) -> int:
    """Bytes of one whole plane of a ``width`` × ``height`` capture."""
    return width * height * PLANE_DTYPE[plane].itemsize


def planes_of(begin: FrameBegin) -> list[Output]:
    """The planes a capture carries (FRAME_BEGIN ``planes``), in the order they are sent."""
    return [p for p in PLANE_ORDER if begin.planes & p]


PlaneSource = Union[np.ndarray, memoryview, Callable[[], np.ndarray]]
"""A plane for ``capture_messages``: its image, its wire bytes, or a function computing the image
when the plane's turn comes."""


def one_plane_bytes(begin: FrameBegin, plane: Output, image: np.ndarray | memoryview | None,
                    copy: bool = False) -> memoryview:
    """The wire bytes of one plane of the capture ``begin`` describes (``copy``: detached from
    ``image``). ValueError if it is missing or does not have the capture's format."""
    if isinstance(image, memoryview):
        if len(image) != plane_size(plane, begin.width, begin.height):
            raise ValueError(f"plane {plane.name}: {len(image)} bytes, expected "
                             f"{plane_size(plane, begin.width, begin.height)}")
        return memoryview(bytes(image)) if copy else image.cast("B")
    if image is None or image.shape != (begin.height, begin.width):
        raise ValueError(f"plane {plane.name}: expected a {begin.height}x{begin.width} image, got "
                         f"{None if image is None else image.shape}")
    data = np.ascontiguousarray(image, dtype=PLANE_DTYPE[plane])
    return (memoryview(data.tobytes()) if copy else data.data).cast("B")


def plane_bytes(begin: FrameBegin, images: Mapping[Output, np.ndarray], copy: bool = False
                ) -> dict[Output, memoryview]:
    """The wire bytes of every plane ``begin.planes`` names (``copy``: detached from ``images``).
    ValueError if a plane image is missing or does not have the capture's format."""
    return {plane: one_plane_bytes(begin, plane, images.get(plane), copy) for plane in planes_of(begin)}


def capture_messages(begin: FrameBegin, images: Mapping[Output, PlaneSource],
                     chunk: int = REFERENCE_CHUNK,
                     on_plane: Callable[[Output, memoryview], None] | None = None) -> Iterator[Message]:
    """FRAME_BEGIN, then every plane of ``begin.planes`` as contiguous FRAME_DATA chunks of at most
    ``chunk`` data bytes, then FRAME_END with the bytes sent per plane. ``images`` are the plane
    images, their bytes from ``plane_bytes``, or functions called when their plane's turn comes
    (after every message before it was taken: a device matches while its images are on the wire).
    ``on_plane`` sees each plane's bytes before its first chunk. ValueError if a plane is missing
    (before FRAME_BEGIN) or has the wrong size (when its turn comes)."""
    if not 0 < chunk <= MAX_PAYLOAD - FRAME_DATA_HEAD:
        raise ValueError(f"chunk of {chunk} bytes; must be 1..{MAX_PAYLOAD - FRAME_DATA_HEAD}")
    planes = planes_of(begin)
    missing = [str(p.name) for p in planes if images.get(p) is None]
    if missing:
        raise ValueError(f"plane {', '.join(missing)}: FRAME_BEGIN names it but no image was given")
    yield begin
    sent = dict.fromkeys(PLANE_ORDER, 0)
    for plane in planes:
        source = images[plane]
        data = one_plane_bytes(begin, plane, source() if callable(source) else source)
        if on_plane is not None:
            on_plane(plane, data)
        for off in range(0, len(data), chunk):
            yield FrameData(begin.sequence, int(plane), off, data[off:off + chunk])
        sent[plane] = len(data)
    yield FrameEnd(begin.sequence, FRAME_OK, sent[Output.LEFT], sent[Output.RIGHT], sent[Output.DISPARITY],
                   sent[Output.CONFIDENCE])
