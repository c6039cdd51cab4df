"""Census codes (census.py, census_simd.census_codes and census_codes_masked) against the numpy
reference, in the layout the SGM kernels read: byte planes per row, the right codes mirrored,
rows padded to 64 codes; with and without the census margin."""
from __future__ import annotations

import numpy as np
import pytest

from stereocam.stereo import SGMMatcher, SGMParams

from tests.support import sgm_reference as ref


@pytest.mark.parametrize("w, cw, ch, paths, margin", [
    (70, 9, 7, 5, 0), (64, 13, 5, 8, 0), (131, 3, 1, 4, 0), (33, 1, 3, 5, 0),
    (70, 9, 7, 5, 9), (64, 13, 5, 8, 9), (131, 3, 1, 4, 9), (33, 1, 3, 5, 9), (17, 3, 3, 5, 9),
    (18, 9, 7, 4, 9), (70, 9, 7, 5, -1), (65, 9, 7, 8, -1)])
def test_census_codes_match_the_reference(w: int, cw: int, ch: int, paths: int,
                                          margin: int) -> None:
    rng = np.random.default_rng(w)
    left = rng.integers(0, 256, (9, w), dtype=np.uint8)
    right = (left // 2 + rng.integers(0, 128, (9, w))).astype(np.uint8)  # another noise level
    p = SGMParams(num_disparities=16, census_width=cw, census_height=ch, paths=paths,
                  census_margin=margin)
    m = SGMMatcher(left.shape, p)
    m.match(left, right)
    wc = m.cl.shape[2]
    assert wc % 64 == 0 and wc >= w
    tl, tr = ref.margin(left, p), ref.margin(right, p)
    assert margin >= 0 or 0 < tl != tr
    np.testing.assert_array_equal(_codes(m.cl[:, :, :w]), ref.census(left, cw, ch, tl))
    np.testing.assert_array_equal(_codes(m.crr[:, :, wc - w:wc][:, :, ::-1]),
                                  ref.census(right, cw, ch, tr))


def _codes(planes: np.ndarray) -> np.ndarray:
    """uint64 codes from byte planes (rows, 8, codes)."""
    assert planes.dtype == np.uint8 and planes.shape[1] == 8
    return sum(planes[:, b].astype(np.uint64) << np.uint64(8 * b) for b in range(8))


@pytest.mark.parametrize("margin", [126, 127, 128, 129, 200, 254])
def test_margins_past_the_signed_byte_range_match_the_reference(margin: int) -> None:
    """The rows are compared as int8 (XOR 0x80) and a margin's bounds made on the uint8 bytes:
    margins from 128 up, on blocks of 0 and 255 whose smoothed steps reach them, still give the
    reference's codes."""
    rng = np.random.default_rng(margin)
    left = (np.kron(rng.integers(0, 2, (4, 20)), np.ones((4, 4), np.int64)) * 255).astype(np.uint8)
    right = np.roll(left, 3, axis=1)
    right[::5] = rng.integers(0, 256, right[::5].shape)  # rows of every level between them
    p = SGMParams(num_disparities=16, census_margin=margin)
    m = SGMMatcher(left.shape, p)
    m.match(left, right)
    w, wc = left.shape[1], m.cl.shape[2]
    want = ref.census(left, 9, 7, margin)
    assert 0 < np.count_nonzero(want) < want.size  # the margin keeps some bits, not all
    np.testing.assert_array_equal(_codes(m.cl[:, :, :w]), want)
    np.testing.assert_array_equal(_codes(m.crr[:, :, wc - w:wc][:, :, ::-1]),
                                  ref.census(right, 9, 7, margin))
