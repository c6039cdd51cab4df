"""``stereocam bench matching --algorithm sgm --pair LEFT RIGHT [--truth FILE]``: a rectified pair
from files as a bench scene, so the table can be made on one's own data (KITTI, Middlebury, ETH3D,
a unit's own recordings), beside the simulator's scenes.

Images: whatever OpenCV decodes, colour turned grey (cv2.IMREAD_GRAYSCALE). Truth, the left
image's disparity in pixels: PFM (Middlebury, ETH3D; inf or NaN where unknown), a 16-bit PNG
(KITTI: value / 256, 0 unknown), .npy (float; non-finite unknown). ``scale`` replaces a PNG's
divisor (an 8-bit PNG, which no format fixes, needs one) and divides a PFM's or .npy's values too.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from stereocam.input_files import read_regular
from stereocam.protocol.errors import InputFileError
from stereocam.stereo import MatchParams, SGMParams, geometry, sgm_geometry

from ..image_files import MAX_IMAGE_BYTES, decode, read_pair
from .matching_report import BenchScene

DEFAULT_DISPARITIES = 128  # with no truth to take the range from
KITTI_SCALE = 256.0


def load_truth(path: Path, scale: float | None) -> np.ndarray:
    """The disparity truth in ``path`` (float32 px, NaN where unknown); see the module docstring."""
    import cv2

    suffix = path.suffix.lower()
    if suffix == ".npy":
        try:
            raw = np.load(io.BytesIO(read_regular(path, what="truth", limit=MAX_IMAGE_BYTES)), allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise InputFileError(f"{path}: not a numpy array file ({exc})") from exc
        if raw.ndim != 2 or raw.dtype.kind not in "fiu":
            raise InputFileError(f"{path}: a disparity array must be 2-D numbers, got {raw.dtype} {raw.shape}")
        truth = raw.astype(np.float32) / np.float32(scale or 1.0)
    else:
        raw = decode(path, cv2.IMREAD_UNCHANGED, "disparity image")
        if raw.ndim != 2:
            raise InputFileError(f"{path}: a disparity image must have one channel, got {raw.shape[2]}")
        if raw.dtype.kind == "f":  # PFM
            truth = raw.astype(np.float32) / np.float32(scale or 1.0)
        else:
            if scale is None:
                if raw.dtype != np.uint16:
                    raise InputFileError(f"{path}: an {raw.dtype} disparity image needs --truth-scale "
                                         "(disparity = pixel value / scale)")
                scale = KITTI_SCALE
            truth = np.where(raw == 0, np.nan, raw.astype(np.float32) / np.float32(scale))
    return np.where(np.isfinite(truth), truth, np.nan).astype(np.float32)


def range_for(truth: np.ndarray | None) -> int:
    """Disparities to search: past the truth's largest, rounded up to 16; DEFAULT_DISPARITIES
    without truth."""
    if truth is None or not np.isfinite(truth).any():
        return DEFAULT_DISPARITIES
    top = float(np.nanmax(truth))
    return max(16, (int(np.floor(top)) // 16 + 1) * 16)


def pair_scene(left: Path, right: Path, truth_path: Path | None, num_disparities: int | None,
               scale: float | None) -> BenchScene:
    """The bench scene of one pair (name: the left file's name)."""
    a, b = read_pair(left, right)
    truth = None
    if truth_path is not None:
        truth = load_truth(truth_path, scale)
        if truth.shape != a.shape:
            raise InputFileError(f"{truth_path} is {truth.shape[1]}x{truth.shape[0]} but the images are "
                                 f"{a.shape[1]}x{a.shape[0]}")
    nd = num_disparities or range_for(truth)
    h, w = a.shape
    geometry(h, w, MatchParams(num_disparities=nd, block_size=9))  # the bench's block matcher
    sgm_geometry(h, w, SGMParams(num_disparities=nd))  # ConfigError now, not after the warm-up
    known = truth if truth is not None else np.full(a.shape, np.nan, np.float32)
    return BenchScene(left.name, a, b, known, nd)
