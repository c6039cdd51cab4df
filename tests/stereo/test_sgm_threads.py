"""The matching engines' numba threads wait passively (OpenMP): a spinning thread takes the
core from the one it waits for when the machine is busy."""
from __future__ import annotations

import os
import subprocess
import sys

CHECK = "import os, stereocam.stereo; print(os.environ.get('OMP_WAIT_POLICY'))"


def run_with(env: dict[str, str]) -> str:
    out = subprocess.run([sys.executable, "-c", CHECK], env=env, capture_output=True, text=True,
                         check=True, timeout=120)
    return out.stdout.strip()


def test_import_sets_passive_waits_unless_the_user_chose() -> None:
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    assert run_with(env) == "PASSIVE"
    assert run_with({**env, "OMP_WAIT_POLICY": "ACTIVE"}) == "ACTIVE"
