"""A hostile or broken device must not silently kill the host (issue 9, items 3, 4)."""
from __future__ import annotations

import time

import pytest

import stereocam
from stereocam.camera import Camera
from stereocam.device_sim import SimulatedCamera
from stereocam.device_sim.links.inprocess import InProcessTransport
from stereocam.frames import FrameAssembler
from stereocam.clock import ClockMap
from stereocam.link import Link
from stereocam.protocol import messages as m

from stereocam.device_sim.link_layer.refusal import Refusal
from tests.support.faults import FaultyTransport
from tests.support.waiting import stays, wait_until


def _begin(width: int, height: int, planes: int = 7, sequence: int = 1) -> m.FrameBegin:
    return m.FrameBegin(sequence, 0, 0, 1000, 0, width, height, planes, 0, m.DISPARITY_S16_Q4, 16, 0, 64, -16, 0,
                        0.0, 0.0, 0.0, 0.0)


def _inject_once(wire: bytes):
    sent = []

    def manipulator(b: bytes) -> bytes:
        if not sent:
            sent.append(True)
            return wire + b
        return b
    return manipulator


def test_an_exception_in_the_event_path_ends_the_link_with_a_typed_error():
    sim = SimulatedCamera(seed=21)
    link_t = FaultyTransport(InProcessTransport(sim))

    def explode(msg: m.Message) -> None:
        raise MemoryError("simulated allocation failure in the event path")

    lk = Link(link_t, timeout=0.3, retries=0, on_event=explode)
    try:
        assert isinstance(lk.request(m.GetInfo()), m.Info)
        link_t.set_manipulator(read=_inject_once(m.encode(_begin(64, 48))))
        wait_until(lambda: not lk.alive, 5, "the link down after its event path failed")
        assert isinstance(lk.error, stereocam.DisconnectedError)  # auto_reconnect acts on it
        assert isinstance(lk.error.__cause__, MemoryError)
        with pytest.raises(stereocam.DisconnectedError, match="MemoryError"):
            lk.request(m.GetInfo())  # at once, not after a timeout
    finally:
        lk.close()


@pytest.mark.parametrize("width,height,planes", [(65535, 65535, 7), (1281, 480, 1), (640, 961, 1), (0, 480, 1),
                                                 (640, 480, 0x80)])
def test_frame_begin_beyond_the_negotiated_limits_is_dropped_not_allocated(width, height, planes):
    delivered: list = []
    asm = FrameAssembler(ClockMap(), delivered.append)
    asm.set_limits(max_width=1280, max_height=960)
    asm.on_message(_begin(width, height, planes))
    asm.on_message(m.FrameData(1, 1, 0, b"\x00" * 16))
    asm.on_message(m.FrameEnd(1, m.FRAME_OK, width * height, 0, 0))
    assert asm.stats.bad_leaders == 1
    assert asm._cur is None and not delivered


def test_frame_data_outside_its_plane_marks_the_capture_bad():
    delivered: list = []
    asm = FrameAssembler(ClockMap(), delivered.append)
    asm.set_limits(max_width=1280, max_height=960)
    asm.on_message(_begin(16, 8, 1))
    asm.on_message(m.FrameData(1, 1, 0xFFFFFFF0, b"\x01" * 32))
    asm.on_message(m.FrameEnd(1, m.FRAME_OK, 128, 0, 0))
    assert asm.stats.size_mismatch == 1 and not delivered


def test_no_frame_is_assembled_before_the_limits_are_known():
    delivered: list = []
    asm = FrameAssembler(ClockMap(), delivered.append)
    asm.on_message(_begin(16, 8, 1))
    assert asm.stats.bad_leaders == 1


def test_a_camera_survives_a_huge_frame_begin_and_keeps_streaming():
    sim = SimulatedCamera(seed=22)
    t = FaultyTransport(InProcessTransport(sim))
    cam = Camera(t, timeout=1.0)
    try:
        cam.configure(width=320, height=240, num_disparities=32, block_size=11, fps=10)
        t.set_manipulator(read=_inject_once(m.encode(_begin(65535, 65535, 7, sequence=999))))
        cam.start()
        frame = cam.get_frame(timeout=10)
        assert frame.width == 320 and cam.alive
        assert cam.stats["bad_leaders"] == 1
    finally:
        cam.close()


def _watchdog_stop(cam: Camera, t: FaultyTransport, sim: SimulatedCamera) -> None:
    """Lose every host-to-device byte until the device's watchdog stops the stream, then heal."""
    t.set_manipulator(write=lambda b: b"")
    wait_until(lambda: sim.counters["heartbeat_timeouts"] and not sim.engine.streaming, 10, "the watchdog's stop")
    assert sim.counters["heartbeat_timeouts"] == 1
    t.set_manipulator(write=lambda b: b)


@pytest.fixture
def streaming():
    sim = SimulatedCamera(seed=23)
    t = FaultyTransport(InProcessTransport(sim))
    cam = Camera(t, timeout=0.3, retries=1, heartbeat_interval=0.1)
    # the device stops the stream after 1.5 s of silence and drops the link after 3 s: room for a
    # loaded machine to heal the link in between (_watchdog_stop)
    cam.configure(width=320, height=240, num_disparities=32, block_size=11, fps=20, heartbeat_timeout_ms=1500)
    cam.start()
    cam.get_frame(timeout=10)
    yield cam, t, sim
    cam.close()


def test_a_stream_the_device_watchdog_stopped_is_restarted(streaming):
    cam, t, sim = streaming
    _watchdog_stop(cam, t, sim)
    at_stop = sim.engine.sequence
    frame = cam.get_frame(timeout=10)
    while frame.sequence <= at_stop:  # frames queued before the stop
        frame = cam.get_frame(timeout=10)  # then the heartbeat saw streaming=False and sent START once
    assert sim.engine.streaming and cam.stream_restarts == 1


def test_a_stream_that_cannot_be_restarted_raises(streaming):
    cam, t, sim = streaming

    def refuse(_msg):
        raise Refusal(stereocam.ErrorCode.BAD_STATE, "sensor fault")
    sim.dispatcher.handlers[m.MsgType.START] = refuse
    _watchdog_stop(cam, t, sim)
    with pytest.raises(stereocam.StreamStoppedError, match="sensor fault"):
        for _ in range(100):
            cam.get_frame(timeout=10)
    assert cam.stream_restarts == 0
    with pytest.raises(stereocam.StreamStoppedError):
        cam.get_frame(timeout=1)  # until the user starts again
    sim.dispatcher.handlers[m.MsgType.START] = sim.streaming.start
    cam.start()
    assert cam.get_frame(timeout=10).width == 320


def test_a_stop_by_the_user_is_not_undone(streaming):
    cam, t, sim = streaming
    for _ in range(20):
        cam.stop()
        time.sleep(0.03)
        cam.start()
    cam.stop()
    assert stays(lambda: not sim.engine.streaming and cam.stream_restarts == 0, 0.5)


def test_auto_reconnect_rides_through_a_failed_event_path():
    cam = stereocam.open("sim://?seed=24", timeout=1.0, auto_reconnect=True)
    try:
        cam.configure(width=320, height=240, num_disparities=32, block_size=11, fps=10)
        cam.start()
        cam.get_frame(timeout=10)
        broken = cam.connection.link

        def explode(msg: m.Message) -> None:
            raise RuntimeError("bug in a frame listener")
        broken._on_event = explode  # this link's event path fails at the next frame message
        frame = cam.get_frame(timeout=15)  # LinkFailedError is a DisconnectedError: reconnect, resume
        assert isinstance(broken.error, stereocam.LinkFailedError) and not broken.alive
        assert cam.connection.link is not broken and cam.alive and frame.width == 320
    finally:
        cam.close()


def test_a_stale_reply_of_another_type_is_stray_not_an_error():
    """A reply left in a pty by an earlier session (same request id, other type) must not fail the
    new session's request: it is counted stray and the real reply is awaited."""
    sim = SimulatedCamera(seed=25)
    t = FaultyTransport(InProcessTransport(sim))
    done = []

    def stale_first(b: bytes) -> bytes:
        if b and not done:
            done.append(True)
            stale_nack = m.Nack(m.MsgType.STOP, int(stereocam.ErrorCode.BUSY), 0, "an earlier session's")
            return m.encode(m.Stopped(), 1) + m.encode(stale_nack, 1) + b
        return b
    t.set_manipulator(read=stale_first)
    lk = Link(t, timeout=1.0, retries=0)
    try:
        assert isinstance(lk.request(m.GetInfo()), m.Info)
        assert lk.stats.stray_replies == 2
    finally:
        lk.close()
        sim.close()
