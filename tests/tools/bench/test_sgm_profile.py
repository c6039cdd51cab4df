"""The 5-path stage profile (bench matching --profile) times the engine's own work: its cut
row loop, run whole, and the speckle halves give the matcher's output."""
from __future__ import annotations

import numpy as np
import pytest

from stereocam.stereo import SGMMatcher, SGMParams
from stereocam.tools.bench.sgm_profile import SINGLE_PASS_STAGES, cpu_ratios, single_pass_rows, \
    speckle_halves, stage_ms


@pytest.mark.parametrize("h", [31, 32])  # halves of unequal and equal height
def test_single_pass_stages_rebuild_the_match(h: int) -> None:
    rng = np.random.default_rng(h)
    base = rng.integers(0, 256, (h, 112), dtype=np.uint8)
    left, right = base[:, 0:96].copy(), base[:, 6:102].copy()  # disparity 6
    m = SGMMatcher(left.shape, SGMParams(num_disparities=32))
    want = m.match(left, right)
    rows = np.empty(m.shape, np.int16)
    single_pass_rows(m, left, right, len(SINGLE_PASS_STAGES), rows)
    speckle_halves(m, rows)
    assert np.array_equal(rows, want)
    # a wall at disparity 6 (in 1/16 px); the ground step may pull the lower half by < 0.12 px (test_sgm_ground)
    assert abs(np.median(want[:, 40:]) - 6 * 16) <= 1


def test_stage_names() -> None:
    img = np.random.default_rng(0).integers(0, 256, (24, 64), dtype=np.uint8)
    m = SGMMatcher(img.shape, SGMParams(num_disparities=16))
    assert list(stage_ms(m, img, np.roll(img, -3, axis=1), 1)) == [
        *SINGLE_PASS_STAGES, "speckle (halves)", "rest of match"]


def test_cpu_ratios_interleave_the_rounds() -> None:
    calls: list[str] = []

    def spin(name: str, n: int):
        def fn() -> None:
            calls.append(name)
            sum(range(n))
        return fn
    base_ms, ratios = cpu_ratios(spin("base", 20_000), [spin("a", 20_000), spin("b", 40_000)], 3)
    assert calls == ["base", "a", "b"] * 4  # a warm-up round, then 3 timed
    assert base_ms >= 0 and [len(r) for r in ratios] == [3, 3]
    assert all(t >= 0 for r in ratios for t in r)
