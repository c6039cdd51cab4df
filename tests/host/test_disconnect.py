"""A device that vanishes mid-stream: typed DisconnectedError within the timeout, never a hang."""
from __future__ import annotations

import time

import pytest

import stereocam
from stereocam.device_sim.process import ServedSimulator
from stereocam.tools.conformance.budget import budget
from tests.support.waiting import wait_until

pytestmark = pytest.mark.sim_only("kills and restarts the simulator process")


@pytest.mark.parametrize("spec", ["pty", "tcp:127.0.0.1:0"])
def test_device_killed_mid_stream(spec):
    server = ServedSimulator(spec, seed=41)
    try:
        cam = stereocam.open(server.url, timeout=1.0)
        cam.configure(width=320, height=240, num_disparities=32, block_size=11, fps=10)
        cam.start()
        cam.get_frame(timeout=30)
        server.proc.kill()
        server.proc.wait()
        t0 = time.monotonic()
        with pytest.raises(stereocam.DisconnectedError):
            for _ in range(100):
                cam.get_frame(timeout=1.0)
        assert time.monotonic() - t0 < budget(3.0)
        with pytest.raises(stereocam.DisconnectedError):
            cam.config()
        cam.close()  # closing a dead camera is quiet
    finally:
        if server.proc.poll() is None:
            server.stop()


def test_a_client_that_stops_reading_does_not_wedge_the_device():
    import socket
    import threading

    from stereocam.device_sim import SimulatedCamera
    from stereocam.device_sim.links.servers import TcpServer
    from stereocam.protocol import messages as m

    sim = SimulatedCamera(seed=42)
    server = TcpServer(sim, send_timeout=0.5)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        wedged = socket.create_connection(server.address)
        wedged.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        wedged.sendall(m.encode(m.Start(), 1))  # starts 640x480 streaming, then never reads a byte
        # it streams; then the stalled send (0.5 s) drops that host and stops the stream
        wait_until(lambda: sim.engine.captured >= 1 and not sim.engine.streaming and not sim.attached,
                   timeout=10, what="the stalled host is dropped")
        with stereocam.open(server.url, timeout=2.0) as cam:  # the next host gets the camera
            assert cam.info().serial == sim.serial
        wedged.close()
    finally:
        server.shutdown()
        thread.join(timeout=5)
        server.close()
        sim.close()
