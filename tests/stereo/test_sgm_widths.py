"""The SGM kernels' vector width follows the CPU numba compiles for (simd.LANES: 64 lanes with
AVX-512, 32 with AVX2, 16 below), and below 512 bits the vertical paths load a run's
neighbours instead of shuffling them (sgm_simd.LOAD_NEIGHBOURS). This machine's own width
runs in the rest of the suite; here the next narrower x86 width is compiled in a child process
(numba's NUMBA_CPU_NAME / NUMBA_CPU_FEATURES, its own cache) and checked bit for bit against
the reference."""
from __future__ import annotations

import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest

from stereocam.stereo import simd

TARGETS = {  # lanes: (NUMBA_CPU_NAME, NUMBA_CPU_FEATURES)
    16: ("x86-64-v2", "+sse4.2,+sse4.1,+ssse3,+popcnt,-avx,-avx2,-avx512f,-avx512bw"),
    32: ("x86-64-v3", "+avx2,+avx,+fma,+bmi2,+popcnt,+sse4.2,-avx512f,-avx512bw"),
}

CHECK = '''
import sys
import numpy as np
from stereocam.stereo import SGMMatcher, SGMParams, simd, sgm_simd
sys.path.insert(0, {tests!r})
from support.sgm_reference import sgm as reference
assert simd.LANES == {lanes}, simd.LANES
assert sgm_simd.LOAD_NEIGHBOURS
rng = np.random.default_rng(7)
for h, w, nd, paths in ((23, 96, 48, 5), (18, 160, 128, 5), (12, 80, 64, 8)):
    left = rng.integers(0, 256, (h, w), dtype=np.uint8)
    right = np.roll(left, -5, axis=1)
    right[:, -5:] = rng.integers(0, 256, (h, 5), dtype=np.uint8)
    p = SGMParams(num_disparities=nd, paths=paths)
    got = SGMMatcher(left.shape, p).match(left, right)
    assert np.array_equal(got, reference(left, right, p)), (h, w, nd, paths)
print("ok")
'''


def _narrower() -> int | None:
    """The next narrower width this machine can run (x86 only): AVX2 on an AVX-512 machine,
    SSE4.2 on an AVX2 one (each compile takes a minute or more, so one width per run)."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return None
    return max((lanes for lanes in TARGETS if lanes < simd.LANES), default=None)


@pytest.mark.slow
def test_a_narrower_vector_width_gives_the_reference_output(tmp_path: Path) -> None:
    lanes = _narrower()
    if lanes is None:
        pytest.skip(f"no narrower x86 width than this machine's {simd.LANES} lanes")
    name, features = TARGETS[lanes]
    env = dict(os.environ, NUMBA_CPU_NAME=name, NUMBA_CPU_FEATURES=features,
               NUMBA_CACHE_DIR=str(tmp_path))
    code = CHECK.format(tests=str(Path(__file__).parents[1]), lanes=lanes)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip() == "ok"
