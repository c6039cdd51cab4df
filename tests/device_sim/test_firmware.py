"""Simulated firmware behaviour: watchdog, external trigger line, clock mapping, depth truth."""
from __future__ import annotations

import time

import numpy as np
import pytest

import stereocam
from stereocam.device_sim import SimulatedCamera, TriggerLine
from stereocam.device_sim.clock import FakeClock
from stereocam.device_sim.rig.scene import WALL_DISTANCE_M
from stereocam.camera import Camera
from stereocam.device_sim.links.inprocess import InProcessTransport
from tests.support.waiting import wait_until

SMALL = dict(width=320, height=240, num_disparities=32, block_size=11)


def open_sim(sim: SimulatedCamera, **kw) -> Camera:
    cam = Camera(InProcessTransport(sim, owns=True), **kw)
    cam.configure(**SMALL)
    return cam


def test_device_stops_streaming_when_host_goes_silent():
    clock = FakeClock()
    sim = SimulatedCamera(seed=21, timebase=clock)
    with open_sim(sim, heartbeat_interval=3600) as cam:
        cam.configure(heartbeat_timeout_ms=300, fps=5)
        cam.start()
        clock.advance(0.29)  # no heartbeat, no command: at 290 ms the stream still runs ...
        sim.heartbeat.watchdog()
        assert sim.engine.streaming and sim.counters["heartbeat_timeouts"] == 0
        clock.advance(0.02)  # ... the watchdog stops it past 300 ms ...
        wait_until(lambda: not sim.engine.streaming, what="the watchdog stops the stream")
        assert sim.counters["heartbeat_timeouts"] == 1 and sim.attached
        clock.advance(0.28)  # ... and drops the link past twice that (SPEC §9)
        sim.heartbeat.watchdog()
        assert sim.attached
        clock.advance(0.02)
        wait_until(lambda: not sim.attached, what="the watchdog drops the link")
        assert sim.counters["links_dropped"] == 1
        with pytest.raises(stereocam.DisconnectedError):
            cam.status()


def test_heartbeats_keep_the_stream_alive():
    clock = FakeClock()
    sim = SimulatedCamera(seed=22, timebase=clock)
    with open_sim(sim, heartbeat_interval=0.05) as cam:
        cam.configure(heartbeat_timeout_ms=400, fps=5)
        cam.start()
        for _ in range(4):  # 1.2 s of device time, never 400 ms without hearing the host
            clock.advance(0.3)
            wait_until(lambda: sim.link.silent_for() == 0, what="the host's next heartbeat")
        st = cam.status()
        assert st.streaming is True and st.counters["heartbeat_timeouts"] == 0


def test_external_trigger_line_shared_by_two_heads():
    line = TriggerLine()
    heads = [open_sim(SimulatedCamera(seed=s, trigger_line=line)) for s in (31, 32)]
    try:
        for cam in heads:
            cam.set_trigger_mode("external")
            cam.start()
        got: list[list[int]] = [[], []]
        for _ in range(3):  # the next edge once both heads delivered this one's frame
            line.pulse()
            for ids, cam in zip(got, heads):
                ids.append(cam.get_frame(timeout=20).trigger_id)
        assert got[0] == got[1] == [1, 2, 3]
        with pytest.raises(stereocam.DeviceError):
            heads[0].trigger()  # software trigger is refused in external mode
    finally:
        for cam in heads:
            cam.close()


def test_host_time_maps_the_exposure_instant():
    sim = SimulatedCamera(seed=23)  # this unit's crystal drifts and has its own epoch
    with open_sim(sim) as cam:
        cam.set_trigger_mode("software")
        cam.start()
        errs = []
        for _ in range(3):
            cam.trigger()
            f = cam.get_frame(timeout=20)
            errs.append(abs(f.host_time - sim.ground_truth(f.sequence).host_monotonic))
    assert sim.clock.drift != 0 and sim.clock.epoch_us > 0
    assert max(errs) < 0.002  # within 2 ms of the true exposure instant


def test_depth_of_a_flat_wall():
    sim = SimulatedCamera(seed=24, scene="wall")
    with open_sim(sim) as cam:
        cam.configure(width=640, height=480, num_disparities=64, block_size=15)
        cam.set_trigger_mode("software")
        cam.start()
        cam.trigger()
        f = cam.get_frame(timeout=30)
        calibration_id = cam.info().calibration_id
    z = f.depth()
    assert np.isfinite(z).mean() > 0.8
    assert abs(np.nanmedian(z) - WALL_DISTANCE_M) / WALL_DISTANCE_M < 0.01
    truth = sim.ground_truth(f.sequence)  # seen from the rectified left camera, a little tilted
    assert np.allclose(truth.depth_m, WALL_DISTANCE_M, rtol=0.01)
    ok = np.isfinite(z)
    assert np.median(np.abs(z[ok] - truth.depth_m[ok]) / truth.depth_m[ok]) < 0.005
    assert f.rectified and f.geometry.calibration_id == calibration_id != 0
    pts, grey = f.points()
    assert pts.shape[1] == 3 and len(pts) == len(grey) == np.isfinite(z).sum()
    Q = f.geometry.Q
    import cv2

    xyz = cv2.reprojectImageTo3D(f.disparity_px().astype(np.float32), Q)
    assert abs(np.nanmedian(xyz[..., 2][np.isfinite(z)]) - np.nanmedian(z)) < 1e-3


def test_ply_writer(tmp_path):
    pts = np.array([[0, 0, 1], [0.5, -0.5, 2.0]], np.float32)
    n = stereocam.write_ply(tmp_path / "c.ply", pts, np.array([10, 200], np.uint8))
    data = (tmp_path / "c.ply").read_bytes()
    header, body = data.split(b"end_header\n")
    assert n == 2 and b"element vertex 2" in header and len(body) == 2 * 15
    rec = np.frombuffer(body, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("r", "u1"), ("g", "u1"), ("b", "u1")])
    assert rec["z"].tolist() == [1.0, 2.0] and rec["r"].tolist() == [10, 200]


def test_sim_url_options_are_checked():
    with pytest.raises(stereocam.ConfigError, match="seed"):
        stereocam.open("sim://?seed=abc")
    with pytest.raises(stereocam.ConfigError, match="colour"):
        stereocam.open("sim://?colour=red")
    with pytest.raises(stereocam.ConfigError, match="known: lab, wall, board"):
        stereocam.open("sim://?scene=beach")
    with stereocam.open("sim://?seed=5&serial=ABC123") as cam:
        assert cam.info().serial == "ABC123"


def test_unreachable_url_is_a_transport_error():
    with pytest.raises(stereocam.TransportError):
        stereocam.open("socket://127.0.0.1:1", timeout=0.5)


def test_replies_do_not_wait_behind_a_whole_frame():
    """On a slow link a reply slips in between the chunks of a capture being sent."""
    sim = SimulatedCamera(seed=25)
    transport = InProcessTransport(sim, owns=True)
    fifo_put = transport._fifo.put

    def slow_link(data: bytes) -> None:  # ~10 ms per message: a 640x480 capture takes > 0.1 s
        time.sleep(0.01)
        fifo_put(data)

    sim.attach(slow_link)
    with Camera(transport, timeout=2.0) as cam:
        cam.configure(width=640, height=480, fps=30)
        cam.start()
        cam.get_frame(timeout=30)
        latencies = []
        for _ in range(5):
            t0 = time.monotonic()
            cam.status()
            latencies.append(time.monotonic() - t0)
        cam.stop()
    latencies.sort()  # a whole capture is 12 messages, > 0.12 s on this link; one slips in between
    assert latencies[2] < 0.05 and latencies[-1] < 0.12  # (the max with room for a loaded machine)
