"""Census codes (census.py, sgm_simd.census_codes) against the numpy reference, in the layout
the SGM kernels read: left codes per row, right codes mirrored, rows padded to 64 codes."""
from __future__ import annotations

import numpy as np
import pytest

from stereocam.stereo import SGMMatcher, SGMParams

from tests.support import sgm_reference as ref


@pytest.mark.parametrize("w, cw, ch, paths", [(70, 9, 7, 5), (64, 13, 5, 8), (131, 3, 1, 4),
                                              (33, 1, 3, 5)])
def test_census_codes_match_the_reference(w: int, cw: int, ch: int, paths: int) -> None:
    rng = np.random.default_rng(w)
    left, right = (rng.integers(0, 256, (9, w), dtype=np.uint8) for _ in range(2))
    m = SGMMatcher(left.shape, SGMParams(num_disparities=16, census_width=cw,
                                         census_height=ch, paths=paths))
    m.match(left, right)
    wc = m.cl.shape[1]
    assert wc % 64 == 0 and wc >= w
    np.testing.assert_array_equal(m.cl[:, :w], ref.census(left, cw, ch))
    np.testing.assert_array_equal(m.crr[:, wc - w:wc][:, ::-1], ref.census(right, cw, ch))
