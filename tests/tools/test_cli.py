"""The stereocam command and the simulator process, run as a user runs them."""
from __future__ import annotations

import signal
import subprocess
import sys

import numpy as np
import pytest

from stereocam.device_sim.process import ServedSimulator
from stereocam.protocol.framing import VERSION_MAJOR, VERSION_MINOR


def stereocam(*args: str, timeout: float = 180) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "stereocam.tools.cli", *args], capture_output=True, text=True, timeout=timeout)


def test_usage_lists_commands():
    r = stereocam()
    assert r.returncode == 2 and "demo" in r.stderr and "capture" in r.stderr and not r.stdout
    r = stereocam("--help")
    assert r.returncode == 0 and "demo" in r.stdout and "Exit codes" in r.stdout


def test_info():
    r = stereocam("info", "sim://?seed=2")
    assert r.returncode == 0, r.stderr
    assert "config.trigger_mode free_run" in r.stdout and "config.outputs left+right+disparity" in r.stdout
    assert "calibration id " in r.stdout and "source factory generation 1" in r.stdout
    assert "serial SIM00002" in r.stdout and f"protocol {VERSION_MAJOR}.{VERSION_MINOR}" in r.stdout
    assert "config.num_disparities 64" in r.stdout


def test_info_on_a_dead_url_is_a_clean_error():
    r = stereocam("info", "socket://127.0.0.1:1")
    assert r.returncode == 1 and "error" in r.stderr and "Traceback" not in r.stderr


def test_capture_writes_images_disparity_and_cloud(tmp_path):
    r = stereocam("capture", "sim://?seed=3", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    names = sorted(p.name for p in tmp_path.iterdir())
    assert [n.split("_", 1)[1] for n in names] == ["disparity.npy", "disparity.png", "left.png", "points.ply",
                                                   "right.png"]
    disp = np.load(next(tmp_path.glob("*_disparity.npy")))
    assert disp.dtype == np.int16 and disp.shape == (480, 640) and (disp > 0).mean() > 0.5
    assert next(tmp_path.glob("*.ply")).read_bytes().startswith(b"ply\nformat binary_little_endian")


def test_demo_prints_a_summary(tmp_path):
    r = stereocam("demo", "--seconds", "1", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    line = [ln for ln in r.stdout.splitlines() if ln.startswith("summary:")][0]
    fields = dict(kv.split("=") for kv in line.split()[1:])
    assert int(fields["frames"]) >= 1 and float(fields["valid_disparity"].rstrip("%")) > 50
    assert float(fields["depth_error_median"].rstrip("%")) < 2.0
    assert (tmp_path / "demo_points.ply").exists()
    assert "kept up: " in r.stdout or "could not keep up: " in r.stdout


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_served_simulator_exits_cleanly(sig):
    server = ServedSimulator("tcp:127.0.0.1:0")
    assert server.url.startswith("socket://127.0.0.1:")
    server.proc.send_signal(sig)
    assert server.proc.wait(timeout=10) == 0


def test_bad_serve_spec():
    r = subprocess.run([sys.executable, "-m", "stereocam.device_sim", "--serve", "udp:1"], capture_output=True, text=True)
    assert r.returncode != 0 and "tcp:HOST:PORT" in r.stderr
