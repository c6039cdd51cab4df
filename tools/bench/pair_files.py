"""``stereocam bench matching --algorithm sgm --pair LEFT RIGHT [--truth FILE]``: a rectified pair
from files as a bench scene, so the table can be made on one's own data (KITTI, Middlebury, ETH3D,
a unit's own recordings), beside the simulator's scenes.

Images and truth (the left image's disparity) are read by tools/image_files.py: a 16-bit PNG as
KITTI's, PFM as Middlebury's and ETH3D's, .npy.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from stereocam.protocol.errors import InputFileError
from stereocam.stereo import MatchParams, SGMParams, geometry, sgm_geometry

from ..image_files import read_disparity, read_pair
from .matching_report import BenchScene

DEFAULT_DISPARITIES = 128  # with no truth to take the range from


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
        truth = read_disparity(truth_path, scale)
        if truth.shape != a.shape:
            raise InputFileError(f"{truth_path} is {truth.shape[1]}x{truth.shape[0]} but the images are "
                                 f"{a.shape[1]}x{a.shape[0]}")
    nd = num_disparities or range_for(truth)
    h, w = a.shape
    geometry(h, w, MatchParams(num_disparities=nd, block_size=9))  # the bench's block matcher
    sgm_geometry(h, w, SGMParams(num_disparities=nd))  # ConfigError now, not after the warm-up
    known = truth if truth is not None else np.full(a.shape, np.nan, np.float32)
    return BenchScene(left.name, a, b, known, nd)
