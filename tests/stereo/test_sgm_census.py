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
@pytest.mark.parametrize("sparse", [True, False])
def test_census_codes_match_the_reference(w: int, cw: int, ch: int, paths: int,
                                          margin: int, sparse: bool) -> None:
    rng = np.random.default_rng(w)
    left = rng.integers(0, 256, (9, w), dtype=np.uint8)
    right = (left // 2 + rng.integers(0, 128, (9, w))).astype(np.uint8)  # another noise level
    p = SGMParams(num_disparities=16, census_width=cw, census_height=ch, paths=paths,
                  census_margin=margin, census_sparse=sparse)
    m = SGMMatcher(left.shape, p)
    m.match(left, right)
    wc = m.cl.shape[2]
    assert wc % 64 == 0 and wc >= w
    assert m.cl.shape[1] == (4 if p.max_cost <= 32 else 8)  # the planes cost_run reads
    tl, tr = ref.margin(left, p), ref.margin(right, p)
    assert margin >= 0 or 0 < tl != tr
    np.testing.assert_array_equal(_codes(m.cl[:, :, :w]), ref.census(left, cw, ch, tl, sparse))
    np.testing.assert_array_equal(_codes(m.crr[:, :, wc - w:wc][:, :, ::-1]),
                                  ref.census(right, cw, ch, tr, sparse))


def test_the_sparse_census_compares_the_odd_chessboard_neighbours() -> None:
    """9x7 sparse: the 32 neighbours with |dx| + |dy| odd (the four beside the centre and the
    window's corners among them), half the bits of the dense census's 62."""
    assert SGMParams(census_sparse=True).max_cost == 32
    assert SGMParams(census_sparse=False).max_cost == 62
    img = np.full((15, 64), 100, np.uint8)
    bits = []
    for dy, dx in [(0, 1), (1, 0), (-3, -4), (3, 4), (1, 1), (0, 2), (-3, -3)]:
        one = img.copy()
        one[7 + dy, 30 + dx] = 50  # one darker neighbour of pixel (7, 30)
        bits.append(int(ref.census(one, 9, 7, 0, True)[7, 30]).bit_count())
    assert bits == [1, 1, 1, 1, 0, 0, 0]


def _codes(planes: np.ndarray) -> np.ndarray:
    """uint64 codes from byte planes (rows, 4 or 8, codes)."""
    assert planes.dtype == np.uint8 and planes.shape[1] in (4, 8)
    return sum(planes[:, b].astype(np.uint64) << np.uint64(8 * b) for b in range(planes.shape[1]))


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
    want = ref.census(left, 9, 7, margin, True)
    assert 0 < np.count_nonzero(want) < want.size  # the margin keeps some bits, not all
    np.testing.assert_array_equal(_codes(m.cl[:, :, :w]), want)
    np.testing.assert_array_equal(_codes(m.crr[:, :, wc - w:wc][:, :, ::-1]),
                                  ref.census(right, 9, 7, margin, True))


@pytest.mark.parametrize("sparse", [True, False])
def test_the_bit_count_is_the_neighbours_counted(sparse: bool) -> None:
    """max_cost (the largest cost, and the p2 limit) is counted arithmetically, so a huge window is
    refused without listing it; it equals the neighbours census_offsets lists."""
    from stereocam.stereo.sgm_params import census_neighbours

    for cw in range(1, 12, 2):
        for ch in range(1, 12, 2):
            if 2 <= cw * ch <= 129 and (not sparse or cw * ch > 1):
                try:
                    p = SGMParams(num_disparities=16, census_width=cw, census_height=ch, census_sparse=sparse)
                except ValueError:
                    continue  # more than 64 comparisons
                assert p.max_cost == len(census_neighbours(cw, ch, sparse)), (cw, ch)
