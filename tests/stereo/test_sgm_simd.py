"""sgm_simd's split order of the path sums: pixel_paths writes each disparity's sum where
sum_pos says, and add_argmin reads them back as disparities, at every chunk and tail width;
pixel_paths takes each path's previous minimum and P2 as replicated dwords and writes its
minima so."""
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


def _rep(b: int) -> int:
    """Byte b replicated over a dword, as pixel_paths takes and writes minima and P2."""
    return b * 0x01010101


def _step(cost: np.ndarray, prev: np.ndarray, m: int = 0, p2: int = 255) -> np.ndarray:
    """One path step: cost + min(P, min(P[k-1], P[k+1]) + P1, min(m + p2, 255)) - m."""
    p = prev.astype(np.int64)
    lo = np.concatenate(([255], p[:-1]))
    hi = np.concatenate((p[1:], [255]))
    return cost + np.minimum(np.minimum(p, np.minimum(lo, hi) + P1), min(m + p2, 255)) - m


@pytest.mark.parametrize("nd", [16, 32, 48, 64, 80, 112, 128, 208, 256])
def test_sums_land_where_sum_pos_says_and_argmin_reads_disparities(nd: int) -> None:
    rng = np.random.default_rng(nd)
    cost = rng.integers(0, 64, nd).astype(np.uint8)
    lbuf = np.zeros(6 * STRIDE, np.uint8)  # runs at 1, 2 (read) and 3, 4 (written) strides
    prev = [rng.integers(0, 100, nd).astype(np.uint8) for _ in range(2)]
    lbuf[STRIDE:STRIDE + nd] = prev[0]
    lbuf[2 * STRIDE:2 * STRIDE + nd] = prev[1]
    # path 0 with its predecessor's minimum and a P2 of 40 (min(m + 40, 255) cuts in), path 1
    # with none (P2 255, minimum 0: a path's first pixel)
    m0 = int(prev[0].min())
    meta = (STRIDE, 3 * STRIDE, _rep(40), _rep(m0), 2 * STRIDE, 4 * STRIDE, _rep(255), 0) + (0,) * 9
    acc = np.zeros(nd, np.int16)
    mins = np.zeros(4, np.uint32)
    m, k = _two_paths(cost, lbuf, meta, acc, nd, mins)
    paths = [_step(cost, prev[0], m0, 40), _step(cost, prev[1])]
    want = paths[0] + paths[1]
    pos = _positions(nd)
    assert sorted(pos) == list(range(nd))
    np.testing.assert_array_equal(acc[pos], want)
    assert (m, k) == (want.min(), int(np.argmin(want)))  # the first disparity holding it
    np.testing.assert_array_equal(lbuf[3 * STRIDE:3 * STRIDE + nd], paths[0])
    np.testing.assert_array_equal(lbuf[4 * STRIDE:4 * STRIDE + nd], paths[1])
    assert list(mins[:2]) == [_rep(int(p.min())) for p in paths]
