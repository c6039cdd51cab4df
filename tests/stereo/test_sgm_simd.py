"""sgm_simd's split order of the path sums: pixel_paths writes each disparity's sum where
sum_pos says, and add_argmin reads them back as disparities, at every chunk and tail width."""
from __future__ import annotations

import numba as nb
import numpy as np
import pytest

from stereocam.stereo.sgm_simd import add_argmin, pixel_paths, sum_pos

P1 = 10
STRIDE = 320  # lbuf run stride, above every nd here and a multiple of 64


@nb.njit(cache=False)
def _two_paths(cost, lbuf, meta, acc, nd, mins):
    pixel_paths(cost, 0, lbuf, meta, 2, P1, acc, 0, nd, mins, (P1, P1))
    return add_argmin(acc, 0, None, 0, nd)


@nb.njit(cache=False)
def _positions(nd):
    out = np.empty(nd, np.int64)
    for k in range(nd):
        out[k] = sum_pos(k, nd)
    return out


def _step(cost: np.ndarray, prev: np.ndarray) -> np.ndarray:
    """One path step with P2 255 and a zero minimum: cost + min(P, min(P[k-1], P[k+1]) + P1)."""
    p = prev.astype(np.int64)
    lo = np.concatenate(([255], p[:-1]))
    hi = np.concatenate((p[1:], [255]))
    return cost + np.minimum(p, np.minimum(np.minimum(lo, hi) + P1, 255))


@pytest.mark.parametrize("nd", [16, 32, 48, 64, 80, 112, 128, 208, 256])
def test_sums_land_where_sum_pos_says_and_argmin_reads_disparities(nd: int) -> None:
    rng = np.random.default_rng(nd)
    cost = rng.integers(0, 64, nd).astype(np.uint8)
    lbuf = np.zeros(6 * STRIDE, np.uint8)  # runs at 1, 2 (read) and 3, 4 (written) strides
    prev = [rng.integers(0, 100, nd).astype(np.uint8) for _ in range(2)]
    lbuf[STRIDE:STRIDE + nd] = prev[0]
    lbuf[2 * STRIDE:2 * STRIDE + nd] = prev[1]
    meta = (STRIDE, 3 * STRIDE, 255, 0, 2 * STRIDE, 4 * STRIDE, 255, 0) + (0,) * 9
    acc = np.zeros(nd, np.int16)
    mins = np.zeros(4, np.int16)
    m, k = _two_paths(cost, lbuf, meta, acc, nd, mins)
    want = _step(cost, prev[0]) + _step(cost, prev[1])
    pos = _positions(nd)
    assert sorted(pos) == list(range(nd))
    np.testing.assert_array_equal(acc[pos], want)
    assert (m, k) == (want.min(), int(np.argmin(want)))  # the first disparity holding it
    np.testing.assert_array_equal(lbuf[3 * STRIDE:3 * STRIDE + nd], _step(cost, prev[0]))
