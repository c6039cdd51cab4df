"""Image and disparity files the commands read and write (``match``, ``bench matching --pair``).

Read: checked as regular files of a bounded size before a byte is read (a FIFO would block, a
device never end), then decoded by OpenCV; colour images turned grey. Disparity maps, by suffix: a
16-bit PNG as KITTI's (disparity x 256, 0 no match: a zero disparity is written as 1 / 256 px), PFM
as Middlebury's and ETH3D's (inf no match), .npy (float32, NaN no match). Written whole: a new file
beside the old one, renamed over it once complete."""
from __future__ import annotations

import io
import os
import uuid
from collections.abc import Callable
from pathlib import Path

import numpy as np

from stereocam.input_files import read_regular
from stereocam.protocol.errors import ConfigError, InputFileError

MAX_IMAGE_BYTES = 512 << 20  # far above any camera frame or data set image (an 8K 16-bit PNG is ~100 MB)
DISPARITY_FORMATS = (".png", ".pfm", ".npy")
KITTI_SCALE = 256  # a KITTI disparity PNG holds disparity x 256, 0 where there is none


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


def read_disparity(path: Path, scale: float | None = None) -> np.ndarray:
    """The disparity map in ``path`` (float32 px, NaN where unknown), by its suffix (module docstring);
    ``scale`` replaces a PNG's divisor (an 8-bit PNG, which no format fixes, needs one) and divides a
    PFM's or .npy's values too."""
    import cv2

    suffix = path.suffix.lower()
    if suffix == ".npy":
        try:
            data = read_regular(path, what="disparity map", limit=MAX_IMAGE_BYTES)
            raw = np.load(io.BytesIO(data), allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise InputFileError(f"{path}: not a numpy array file ({exc})") from exc
        if raw.ndim != 2 or raw.dtype.kind not in "fiu":
            raise InputFileError(f"{path}: a disparity array must be 2-D numbers, got {raw.dtype} {raw.shape}")
        disp = raw.astype(np.float32) / np.float32(scale or 1.0)
    else:
        raw = decode(path, cv2.IMREAD_UNCHANGED, "disparity image")
        if raw.ndim != 2:
            raise InputFileError(f"{path}: a disparity image must have one channel, got {raw.shape[2]}")
        if raw.dtype.kind == "f":  # PFM
            disp = raw.astype(np.float32) / np.float32(scale or 1.0)
        else:
            if scale is None:
                if raw.dtype != np.uint16:
                    raise InputFileError(f"{path}: an {raw.dtype} disparity image needs --truth-scale "
                                         "(disparity = pixel value / scale)")
                scale = KITTI_SCALE
            disp = np.where(raw == 0, np.nan, raw.astype(np.float32) / np.float32(scale))
    return np.where(np.isfinite(disp), disp, np.nan).astype(np.float32)


def write_whole(path: Path, write: Callable[[Path], None]) -> None:
    """``write(tmp)`` to a new file beside ``path`` (same suffix: OpenCV picks its encoder by it), then
    that file renamed over ``path``; on any failure the new file is removed and ``path`` is untouched."""
    tmp = path.with_name(f".{path.stem}.{uuid.uuid4().hex[:12]}{path.suffix}")
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def imwrite(image: np.ndarray) -> Callable[[Path], None]:
    """A ``write_whole`` writer of ``image`` by OpenCV (the encoder the path's suffix names)."""
    def write(path: Path) -> None:
        import cv2

        if not cv2.imwrite(str(path), image):
            raise OSError(f"{path}: OpenCV could not write it")
    return write


def write_disparity(path: Path, disparity: np.ndarray) -> None:
    """``disparity`` (float32 px, NaN no match) in the format ``path``'s suffix names (DISPARITY_FORMATS)."""
    suffix = path.suffix.lower()
    known = np.isfinite(disparity)
    if suffix == ".npy":
        write_whole(path, lambda tmp: np.save(tmp, disparity))
    elif suffix == ".pfm":
        write_whole(path, imwrite(np.where(known, disparity, np.inf).astype(np.float32)))
    else:
        if np.nanmin(disparity, initial=0.0) < 0:
            raise ConfigError("a 16-bit PNG holds no negative disparity: write .pfm or .npy")
        # 0 means no match in this format: a zero disparity (a point at infinity) is kept as 1 / 256 px
        code = np.where(known, np.maximum(np.rint(disparity * KITTI_SCALE), 1), 0)
        write_whole(path, imwrite(np.clip(code, 0, 65535).astype(np.uint16)))
