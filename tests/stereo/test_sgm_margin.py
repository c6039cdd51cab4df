"""The census margin (SGMParams.census_margin): the automatic margin follows the image's noise,
is bit-exact with the reference, and on the low-texture scene class finds more of the walls."""
from __future__ import annotations

import numpy as np
import pytest

from stereocam.stereo import SGMMatcher, SGMParams
from stereocam.stereo.census import laplacian_median, noise_margin

from tests.support import sgm_reference as ref


@pytest.mark.parametrize("shape", [(1, 1), (2, 40), (40, 2), (3, 3), (17, 29), (64, 65)])
def test_laplacian_median_matches_reference(shape: tuple[int, int]) -> None:
    img = np.random.default_rng(shape[1]).integers(0, 256, shape, dtype=np.uint8)
    assert laplacian_median(img) == ref.laplacian_median(img)


def test_margin_follows_noise() -> None:
    rng = np.random.default_rng(1)
    ramp = np.tile(np.arange(0, 200, 2, dtype=np.uint8), (60, 1))  # no second derivative
    assert noise_margin(ramp) == 0
    noisy = np.clip(ramp + rng.normal(0, 6, ramp.shape), 0, 255).astype(np.uint8)
    cleaner = np.clip(ramp + rng.normal(0, 2, ramp.shape), 0, 255).astype(np.uint8)
    assert noise_margin(noisy) > noise_margin(cleaner) >= 0
    assert noise_margin(noisy) >= 2


def _bad(disp: np.ndarray, truth: np.ndarray, invalid: int) -> float:
    known = np.isfinite(truth)
    bad = (disp == invalid) | (np.abs(disp / 16.0 - np.where(known, truth, 0)) > 2.0)
    return float((bad & known).sum() / known.sum())


def test_low_texture_walls_gain_from_the_margin() -> None:
    """Walls at 2 % print contrast, where the sensor noise is most of the signal: the plain
    census sums noise; with the automatic margin the paths carry the walls' edges inward."""
    from stereocam.device_sim.rig.stereo_pair import render_pair

    pair = render_pair("low-texture", 240, 180, seed=0)
    p = SGMParams(num_disparities=32)
    assert noise_margin(pair.left) > 0
    auto = SGMMatcher(pair.left.shape, p).match(pair.left, pair.right)
    np.testing.assert_array_equal(auto, ref.sgm(pair.left, pair.right, p))
    plain = SGMParams(num_disparities=32, census_margin=0)
    off = SGMMatcher(pair.left.shape, plain).match(pair.left, pair.right)
    # 0.63 against 0.69 bad-2.0 with the sparse census; the dense one's plain census sums more
    # noise (0.60 against 0.74)
    assert _bad(auto, pair.disparity, p.invalid_value) < _bad(off, pair.disparity, p.invalid_value) - 0.04
