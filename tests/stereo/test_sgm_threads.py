"""The matching engines' numba threads wait passively (OpenMP): a spinning thread takes the
core from the one it waits for when the machine is busy."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from tests.support.hangs import terminated

CHECK = "import os, stereocam.stereo; print(os.environ.get('OMP_WAIT_POLICY'))"


def run_with(env: dict[str, str]) -> str:
    out = subprocess.run([sys.executable, "-c", CHECK], env=env, capture_output=True, text=True,
                         check=True, timeout=120)
    return out.stdout.strip()


def test_import_sets_passive_waits_unless_the_user_chose() -> None:
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    assert run_with(env) == "PASSIVE"
    assert run_with({**env, "OMP_WAIT_POLICY": "ACTIVE"}) == "ACTIVE"


MATCH = """
import sys, numpy as np
from stereocam.stereo import SGMMatcher, SGMParams
rng = np.random.default_rng(5)
base = rng.integers(0, 256, (60, 200), dtype=np.uint8)
left, right = base[:, 8:168].copy(), base[:, 14:174].copy()
m = SGMMatcher(left.shape, SGMParams(num_disparities=32, paths=5))
np.save(sys.argv[1], np.stack([m.match(left, right) for _ in range(3)]))
"""


def test_five_paths_on_more_threads_than_cores(tmp_path) -> None:
    """Four workers on (here) two cores: two per half, each row waiting on the one before
    (spin, then yield); the output is the one-thread output."""
    out = {}
    for n in (1, 4):
        path = tmp_path / f"{n}.npy"
        subprocess.run([sys.executable, "-c", MATCH, str(path)], check=True, timeout=300,
                       env={**os.environ, "NUMBA_NUM_THREADS": str(n)})
        out[n] = np.load(path)
    assert np.array_equal(out[4], out[1])
    assert (out[1] != out[1][0, 0, 0]).any()


MATCH_MANY = """
import json, os, sys, numpy as np
from stereocam.stereo import SGMMatcher, SGMParams
rng = np.random.default_rng(7)
base = rng.integers(0, 256, (120, 360), dtype=np.uint8)
left, right = base[:, 20:340].copy(), base[:, 29:349].copy()
m = SGMMatcher(left.shape, SGMParams(num_disparities=48, paths=5))
frames = [m.match(left, right) for _ in range(int(sys.argv[2]))]
np.save(sys.argv[1], np.stack(frames))
masks = {t: sorted(os.sched_getaffinity(int(t))) for t in os.listdir("/proc/self/task")}
json.dump({"main": sorted(os.sched_getaffinity(0)), "threads": masks}, open(sys.argv[1] + ".json", "w"))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc and CPU masks")
def test_five_paths_on_two_threads_beside_a_busy_process(tmp_path) -> None:
    """Two workers beside a spinning process: the scheduler tends to put both on one CPU, so
    the pool's worker moves to the other (cpus.spread_out); the one sharing a CPU falls
    behind, and the other, done with its half first, takes the late half over after the
    row in progress. Every frame is the one-thread output, and every thread ends with the
    CPU mask it had."""
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        out = {}
        for n, frames in ((1, 1), (2, 40)):
            path = tmp_path / f"{n}.npy"
            subprocess.run([sys.executable, "-c", MATCH_MANY, str(path), str(frames)],
                           check=True, timeout=300, env={**os.environ, "NUMBA_NUM_THREADS": str(n)})
            out[n] = np.load(path)
    finally:
        terminated(busy)
    assert (out[1] != out[1][0, 0, 0]).any()
    for frame in out[2]:
        assert np.array_equal(frame, out[1][0])
    masks = json.loads((tmp_path / "2.npy.json").read_text())
    assert len(masks["threads"]) >= 2  # the caller and the pool's worker
    for mask in masks["threads"].values():  # none left on fewer CPUs than the process has
        assert mask == masks["main"]
