"""Image files a command reads (``match``, ``bench matching --pair``): checked as regular files of a
bounded size before a byte is read (a FIFO would block, a device never end), then decoded by OpenCV."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from stereocam.input_files import read_regular
from stereocam.protocol.errors import InputFileError

MAX_IMAGE_BYTES = 512 << 20  # far above any camera frame or data set image (an 8K 16-bit PNG is ~100 MB)


def decode(path: Path, flags: int, what: str = "image") -> np.ndarray:
    """The image in ``path`` decoded with cv2 ``flags``; InputFileError naming a file that is not a
    regular one, is too large, or is not an image OpenCV can read."""
    import cv2

    data = read_regular(path, what=what, limit=MAX_IMAGE_BYTES)
    img = cv2.imdecode(np.frombuffer(data, np.uint8), flags) if data else None
    if img is None:
        raise InputFileError(f"{path}: not an image that OpenCV can read")
    return img


def read_pair(left: Path, right: Path) -> tuple[np.ndarray, np.ndarray]:
    """Both images as grey levels (colour turned grey); InputFileError as ``decode`` or naming sizes
    that differ."""
    import cv2

    a, b = decode(left, cv2.IMREAD_GRAYSCALE), decode(right, cv2.IMREAD_GRAYSCALE)
    if a.shape != b.shape:
        raise InputFileError(f"{left} is {a.shape[1]}x{a.shape[0]} but {right} is {b.shape[1]}x{b.shape[0]}: "
                             "a rectified pair has one size")
    return a, b
