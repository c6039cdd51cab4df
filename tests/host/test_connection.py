"""Camera over Connection and FrameDispatcher: threads only where needed, counters safe across
threads, get_frame free of link I/O, and the recorder beside get_frame on the same frames."""
from __future__ import annotations

import dataclasses
import threading

import stereocam
from stereocam.camera import Camera
from stereocam.connection import Counters
from stereocam.device_sim import SimulatedCamera
from stereocam.device_sim.links.inprocess import InProcessTransport
from stereocam.protocol import messages as m
from stereocam.recording.reader import Recording
from tests.support.device import SMALL
from tests.support.faults import FaultyTransport, PacketFilter, as_v1_1_info
from tests.support.waiting import wait_until

CAMERA_THREADS = ("stereocam-link", "stereocam-heartbeat", "stereocam-repair", "stereocam-callbacks")


def _camera_threads() -> list[str]:
    return sorted(t.name for t in threading.enumerate() if t.name in CAMERA_THREADS)


def _wait_queued(cam: Camera, n: int, timeout: float = 30.0) -> None:
    wait_until(lambda: len(cam.frames) >= n, timeout, f"{n} frames queued")


def test_an_open_camera_without_repair_runs_two_threads():
    before = _camera_threads()
    sim = SimulatedCamera(seed=31)
    t = FaultyTransport(InProcessTransport(sim))
    t.set_manipulator(read=PacketFilter(as_v1_1_info))
    cam = Camera(t, timeout=2.0)
    try:
        assert not cam.connection.repairing and not cam.connection.info.capabilities & m.Capability.FRAME_REPAIR
        cam.configure(**SMALL, fps=20)
        cam.start()
        cam.get_frame(timeout=10)
        assert _camera_threads() == sorted(before + ["stereocam-heartbeat", "stereocam-link"])
    finally:
        cam.close()
        sim.close()


def test_repair_negotiated_but_never_needed_starts_no_worker():
    before = _camera_threads()
    with stereocam.open("sim://?seed=32", timeout=2.0) as cam:
        assert cam.connection.repairing
        cam.configure(**SMALL, fps=20)
        cam.start()
        cam.get_frame(timeout=10)
        assert "stereocam-repair" not in _camera_threads()
        assert _camera_threads() == sorted(before + ["stereocam-heartbeat", "stereocam-link"])


def test_counters_add_up_under_concurrent_requests():
    with stereocam.open("sim://?seed=33", timeout=2.0, heartbeat_interval=10.0) as cam:
        start = cam.counters()
        threads, per_thread = 6, 40

        def ask():
            for _ in range(per_thread):
                cam.request(m.GetConfig())

        workers = [threading.Thread(target=ask) for _ in range(threads)]
        for w in workers:
            w.start()
        for w in workers:
            w.join(60)
        end = cam.counters()
        assert isinstance(end, Counters) and dataclasses.is_dataclass(end)
        assert end.link.requests - start.link.requests == threads * per_thread
        assert end.link.timeouts == start.link.timeouts == 0
        assert cam.stats["requests"] == end.link.requests


def test_get_frame_sends_nothing_to_the_device():
    sim = SimulatedCamera(seed=34)
    t = FaultyTransport(InProcessTransport(sim))
    cam = Camera(t, timeout=2.0)
    try:
        cam.configure(**SMALL, fps=30)
        stored = cam.read_calibration()
        assert stored is not None  # a calibrated unit: frames get the host-derived geometry
        cam.start()
        _wait_queued(cam, 3)
        writers: list[str] = []

        def note_writer(data: bytes) -> bytes:
            writers.append(threading.current_thread().name)
            return data

        t.set_manipulator(write=note_writer)
        me = threading.current_thread().name
        frames = [cam.get_frame(timeout=10) for _ in range(3)]
        assert me not in writers  # the heartbeat may write meanwhile; this thread never did
        assert all(f.geometry.calibration_id == stored.calibration_id and f.calibration is not None
                   for f in frames)
    finally:
        cam.close()
        sim.close()


def test_the_recorder_and_get_frame_receive_the_same_frames_at_once(tmp_path):
    with stereocam.open("sim://?seed=35", timeout=2.0) as cam:
        cam.configure(**SMALL, fps=20)
        cam.start()
        path = tmp_path / "both.mcap"
        done = threading.Event()
        result: list = []
        recording = threading.Thread(target=lambda: (result.append(cam.record(str(path), frames=8)), done.set()))
        recording.start()
        got: list[int] = []
        while not done.is_set() or len(cam.frames):
            try:
                got.append(cam.get_frame(timeout=0.2).sequence)
            except stereocam.CameraTimeoutError:
                pass
        recording.join(30)
        cam.stop()
        assert result and result[0].frames == 8 and result[0].recorder_dropped == 0
        with Recording(str(path)) as rec:
            recorded = [c.info.sequence for c in rec.captures()]
        assert len(recorded) == 8 and set(recorded) <= set(got)
        assert cam.frames.dropped == 0  # get_frame kept up: it lost nothing to the recorder
