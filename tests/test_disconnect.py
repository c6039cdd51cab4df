"""A device that vanishes mid-stream: typed DisconnectedError within the timeout, never a hang."""
from __future__ import annotations

import time

import pytest

import host
from device_sim.process import ServedSimulator


@pytest.mark.parametrize("spec", ["pty", "tcp:127.0.0.1:0"])
def test_device_killed_mid_stream(spec):
    server = ServedSimulator(spec, seed=41)
    try:
        cam = host.open(server.url, timeout=1.0)
        cam.configure(width=320, height=240, num_disparities=32, block_size=11, fps=10)
        cam.start()
        cam.get_frame(timeout=30)
        server.proc.kill()
        server.proc.wait()
        t0 = time.monotonic()
        with pytest.raises(host.DisconnectedError):
            for _ in range(100):
                cam.get_frame(timeout=1.0)
        assert time.monotonic() - t0 < 3.0
        with pytest.raises(host.DisconnectedError):
            cam.config()
        cam.close()  # closing a dead camera is quiet
    finally:
        if server.proc.poll() is None:
            server.stop()
