"""SGM's ground step (SGMParams.p1_ground_percent): on a textured floor, whose disparity grows
downwards, the 5-path default's vertical and diagonal paths (all from below in the lower half)
no longer lag behind the disparity; a ceiling (the same pair upside down) is no worse; the price,
with 5 paths, is a small shift of walls in the lower half toward smaller disparities."""
from __future__ import annotations

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from stereocam.stereo import SGMMatcher, SGMParams  # noqa: E402
from stereocam.tools.bench.sgm_scenes import slanted_plane  # noqa: E402

H, W, SLOPE = 96, 160, 0.3  # a floor from row H / 4 down, its disparity growing 0.3 px per row


def floor_pair(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(left, right, disparity per row): a low-contrast blurred texture on a floor below the
    horizon row H / 4 (disparity 0 above), each left row the right one shifted by its disparity."""
    rng = np.random.default_rng(seed)
    pad = 40
    tex = 100 + 0.15 * cv2.GaussianBlur(rng.integers(0, 256, (H, W + 2 * pad)).astype(np.float32), (5, 5), 0)
    d = np.maximum(SLOPE * (np.arange(H) - H // 4), 0.0)
    xs = np.arange(W, dtype=np.float32)
    left = np.stack([np.interp(xs - d[y], np.arange(-pad, W + pad), tex[y]) for y in range(H)])
    return left.round().astype(np.uint8), tex[:, pad:pad + W].round().astype(np.uint8), d


def median_error(disp: np.ndarray, truth: np.ndarray, rows: slice, p: SGMParams) -> float:
    """Median signed error in px over the valid pixels of rows, columns clear of both borders."""
    part = disp[rows, 50:150]
    ok = part != p.invalid_value
    assert ok.mean() > 0.9
    return float(np.median((part / 16.0 - truth[rows, None])[ok]))


@pytest.mark.parametrize("seed", [0, 1])
def test_the_ground_step_removes_most_of_the_floor_lag(seed: int) -> None:
    left, right, truth = floor_pair(seed)
    err = {}
    for pct in (100, SGMParams().p1_ground_percent):
        p = SGMParams(num_disparities=48, p1_ground_percent=pct)
        err[pct] = median_error(SGMMatcher(left.shape, p).match(left, right), truth, slice(72, 96), p)
    off, on = err[100], err[SGMParams().p1_ground_percent]
    assert off > 0.25  # the lag: too large a disparity, the paths from below carrying it up
    assert 0 <= on < 0.7 * off


@pytest.mark.parametrize("paths", [5, 8])
def test_a_ceiling_is_no_worse(paths: int) -> None:
    left, right, truth = (np.ascontiguousarray(a[::-1]) for a in floor_pair(0))
    err = {}
    for pct in (100, SGMParams().p1_ground_percent):
        p = SGMParams(num_disparities=48, paths=paths, p1_ground_percent=pct)
        err[pct] = median_error(SGMMatcher(left.shape, p).match(left, right), truth, slice(0, 24), p)
    assert abs(err[SGMParams().p1_ground_percent]) <= abs(err[100]) + 0.05


@pytest.mark.parametrize("paths, most", [(5, 0.12), (8, 0.01)])
def test_walls_in_the_lower_half_shift_little(paths: int, most: float) -> None:
    """A wall (disparity constant down each column, slanted across) is not a floor: with 5
    paths the lower half's paths, all from below, pull it toward smaller disparities (0.09 px
    at 50 %); with 8, paths from above balance them. The upper half stays as without the step."""
    shift = {}
    for pct in (100, SGMParams().p1_ground_percent):
        p = SGMParams(num_disparities=48, paths=paths, p1_ground_percent=pct)
        err = []
        for seed, (slope, d0) in enumerate(((0.05, 10.3), (-0.09, 36.4))):
            left, right, truth = slanted_plane(48, 200, d0, slope, seed)
            disp = SGMMatcher(left.shape, p).match(left, right)
            assert (disp[4:-4, 52:-4] != p.invalid_value).mean() > 0.95
            err.append(disp[4:-4, 52:-4] / 16.0 - truth[4:-4, 52:-4])
        e = np.concatenate(err, axis=1)
        shift[pct] = (float(e[:20].mean()), float(e[20:].mean()))  # upper, lower half
    off, on = shift[100], shift[SGMParams().p1_ground_percent]
    assert abs(on[0] - off[0]) < 0.015  # 8 paths: the lower half's paths reach the upper (0.012)
    assert -most < on[1] - off[1] <= 0.01
