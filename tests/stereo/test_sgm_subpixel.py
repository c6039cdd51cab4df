"""SGM's subpixel estimate is nearly unbiased on slanted planes with exact truth: little pull
toward whole pixels (SGBM_3WAY's parabola pulls by about 0.1 px; ours, 5 paths, equiangular, by
0.043 px with the sparse census and 0.035 with the dense one at the default P1 / P2, whose
smoothing is what pulls)."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("cv2")

from stereocam.stereo import SGMMatcher, SGMParams
from stereocam.tools.bench.sgm_scenes import fraction_bias, slanted_plane


def test_no_pixel_locking_on_slanted_planes() -> None:
    p = SGMParams(num_disparities=48, p1_ground_percent=100)  # the ground step's own shift of
    # walls in the lower half: test_sgm_ground.py
    est, truth = [], []
    for slope, d0 in ((0.05, 10.3), (0.13, 11.1), (-0.09, 36.4)):
        for seed in range(2):
            left, right, gt = slanted_plane(48, 200, d0 + 0.37 * seed, slope, seed)
            disp = SGMMatcher(left.shape, p).match(left, right)
            est.append(disp[4:-4, 52:-4])  # matched columns, away from the borders
            truth.append(gt[4:-4, 52:-4])
    bias, rms = fraction_bias(np.concatenate(est), np.concatenate(truth), p.invalid_value)
    assert np.all(np.abs(bias) < 0.05), f"bias per fraction bin {np.round(bias, 3)}"
    assert rms < 0.2, rms
