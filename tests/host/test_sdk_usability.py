"""The SDK behaves like the ones users know: polling, callbacks, iteration, repr, options, presets.
Against every transport, or the camera given with --device."""
from __future__ import annotations

import json
import logging
import sys
import threading
import time

import pytest

import stereocam
from stereocam.protocol.params import PARAMS
from stereocam.tools.conformance.budget import budget
from tests.support.device import SMALL
from tests.support.waiting import wait_until


@pytest.fixture
def device_cam(device_url):
    from stereocam.protocol.params import defaults

    cam = stereocam.open(device_url, timeout=1.0)
    cam.configure(**{**defaults(), **SMALL, "fps": 30})
    yield cam
    cam.close()


def _wait_queued(cam, n: int = 1, timeout: float = 30.0) -> None:
    wait_until(lambda: len(cam.frames) >= n, timeout, f"{n} frames queued")


def test_get_frame_timeout_zero_polls(device_cam):
    device_cam.start()
    _wait_queued(device_cam)
    device_cam.stop()
    frame = device_cam.get_frame(timeout=0)
    assert isinstance(frame, stereocam.Frame)
    while device_cam.try_get_frame() is not None:
        pass
    t0 = time.monotonic()
    with pytest.raises(stereocam.CameraTimeoutError):
        device_cam.get_frame(timeout=0)
    assert device_cam.try_get_frame() is None
    assert time.monotonic() - t0 < budget(0.5)


def test_callbacks_run_off_the_reader_thread_and_report_errors(device_cam, caplog):
    seen: list[tuple[int, str]] = []
    got = threading.Event()

    def record(frame):
        seen.append((frame.sequence, threading.current_thread().name))
        got.set()

    def broken(frame):
        raise ValueError(f"boom on {frame.sequence}")

    device_cam.on_frame(record)
    device_cam.on_frame(broken)
    with caplog.at_level(logging.ERROR):
        device_cam.start()
        assert got.wait(30)
        wait_until(lambda: device_cam.callback_errors, 10, "a callback error counted")
    assert seen and all(name != device_cam.connection.link._reader.name for _, name in seen)
    assert device_cam.callback_errors >= 1
    assert any("boom on" in r.getMessage() for r in caplog.records)
    with pytest.raises(stereocam.CallbackError) as info:
        device_cam.check_callbacks()
    assert isinstance(info.value.__cause__, ValueError)
    with pytest.raises(stereocam.StereoCamError, match="callbacks"):
        device_cam.get_frame(timeout=0.1)
    device_cam.remove_callback(record)
    device_cam.remove_callback(broken)
    _wait_queued(device_cam, 3)  # with no callback left, frames stay for get_frame
    assert device_cam.get_frame(timeout=0).sequence > 0


def test_iteration_ends_when_stopped(device_cam):
    device_cam.start()
    device_cam.get_frame(timeout=30)
    frames = []
    for frame in device_cam:
        frames.append(frame)
        if len(frames) == 3:
            threading.Thread(target=device_cam.stop).start()
    assert len(frames) >= 3


def test_iteration_raises_on_a_stall(device_cam):
    device_cam.set_trigger_mode("software")
    device_cam.start()
    t0 = time.monotonic()
    with pytest.raises(stereocam.StreamStalledError) as info:
        for _ in device_cam:
            pass
    assert isinstance(info.value, TimeoutError) and time.monotonic() - t0 >= device_cam.timeout * 0.9


def test_iterating_a_stopped_camera_says_so(device_cam):
    with pytest.raises(stereocam.StereoCamError, match="start"):
        next(iter(device_cam))


def test_iteration_ends_when_closed_from_another_thread(device_cam):
    """It raised TransportError('link closed') most times; and ``streaming`` stayed True."""
    device_cam.start()
    device_cam.get_frame(timeout=30)
    closer = threading.Thread(target=device_cam.close)
    frames = []
    for frame in device_cam:  # ends, raises nothing
        frames.append(frame)
        if len(frames) == 2:
            closer.start()
    closer.join(budget(10))
    assert len(frames) >= 2 and not closer.is_alive()
    assert not device_cam.streaming and repr(device_cam).endswith(" closed>")
    assert list(device_cam) == []  # a closed camera's stream is over


def test_iteration_still_raises_when_the_link_fails():
    with stereocam.open("sim://?seed=3") as cam:
        cam.configure(**SMALL)
        cam.start()
        cam.get_frame(timeout=30)
        cam.connection.link.fail(RuntimeError("injected"))
        with pytest.raises(stereocam.DisconnectedError, match="injected"):
            for _ in cam:
                pass
        assert cam.streaming  # the user's stream, not closed: reconnect() resumes it


def test_a_callback_raising_system_exit_is_reported_and_delivery_goes_on():
    """SystemExit ended the callbacks thread: not counted, later callbacks got nothing."""
    with stereocam.open("sim://?seed=3") as cam:
        cam.configure(**SMALL, fps=30)

        def leave(frame):
            sys.exit("from a callback")

        cam.on_frame(leave)
        cam.start()
        wait_until(lambda: cam.callback_errors >= 2, 30, "SystemExit counted twice")
        with pytest.raises(stereocam.CallbackError) as info:
            cam.check_callbacks()
        assert isinstance(info.value.__cause__, SystemExit)
        cam.remove_callback(leave)
        got = threading.Event()
        cam.on_frame(lambda frame: got.set())
        assert got.wait(budget(10))
        with pytest.raises(stereocam.StereoCamError, match="callbacks"):
            cam.get_frame(timeout=0)


def test_close_waits_for_a_running_callback():
    """close() left the callbacks thread running a slow callback."""
    cam = stereocam.open("sim://?seed=3")
    cam.configure(**SMALL, fps=30)
    running, release = threading.Event(), threading.Event()

    def slow(frame):
        running.set()
        release.wait(budget(10))

    cam.on_frame(slow)
    cam.start()
    assert running.wait(budget(30))
    threading.Timer(0.1, release.set).start()  # well within close()'s wait (callbacks.CLOSE_WAIT)
    cam.close()
    assert not cam._callbacks._thread.is_alive()


def test_frame_repr_is_short(device_cam):
    device_cam.start()
    frame = device_cam.get_frame(timeout=30)
    text = repr(frame)
    assert len(text) < 160 and "array" not in text
    assert f"sequence={frame.sequence}" in text and "320x240" in text and "left+right+disparity" in text


def test_options_list_every_parameter_with_range_unit_default_description(device_cam):
    options = {p.name: p for p in device_cam.options()}
    assert set(options) == {p.name for p in PARAMS}
    assert all(p.description and p.lo <= p.default <= p.hi for p in options.values())
    assert options["exposure_us"].unit == "us" and options["fps"].hi == 120


def test_presets_round_trip_and_refusals_change_nothing(device_cam, tmp_path):
    device_cam.configure(exposure_us=1234, gain=50, block_size=21)
    path = tmp_path / "indoor.json"
    saved = device_cam.save_preset(path)
    assert json.loads(path.read_text())["config"]["exposure_us"] == 1234
    device_cam.configure(exposure_us=9000, gain=0, block_size=5)
    assert device_cam.load_preset(path) == saved == device_cam.config()

    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"format": "stereocam-preset/1", "config": {"exposure_us": 5, "gain": 10}}))
    before = device_cam.config()
    with pytest.raises(stereocam.DeviceError):
        device_cam.load_preset(bad)
    assert device_cam.config() == before
    (tmp_path / "junk.json").write_text("[1, 2]")
    with pytest.raises(stereocam.ConfigError, match="not a stereocam preset"):
        device_cam.load_preset(tmp_path / "junk.json")


def test_camera_and_group_say_what_they_are():
    cam = stereocam.open("sim://?seed=3")
    assert repr(cam) == "<Camera sim://?seed=3 STOC-SIM serial=SIM00003 firmware=1.1.0 stopped>"
    cam.close()
    assert repr(cam).endswith(" closed>")
    group = stereocam.CameraGroup(["sim://?seed=1&line=R", "sim://?seed=2&line=R"], master=1)
    assert repr(group) == "<CameraGroup sim://?seed=1&line=R, sim://?seed=2&line=R master=1 not opened>"


def test_get_frame_before_start_says_so_at_once():
    """It waited for its whole timeout and raised a bare timeout."""
    with stereocam.open("sim://?seed=3") as cam:
        with pytest.raises(stereocam.CameraTimeoutError, match=r"not streaming \(call start\(\) before get_frame"):
            cam.get_frame(timeout=600)  # at once, or the test's own (180 s) timeout fails it
