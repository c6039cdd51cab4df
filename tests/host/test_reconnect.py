"""Unplug, replug (same serial), reconnect: the configuration comes back and streaming resumes."""
from __future__ import annotations

import contextlib
import time

import numpy as np
import pytest

import stereocam.device_sim.usb as simusb
import stereocam
from stereocam.device_sim import SimulatedCamera
from stereocam.dispatch import FrameQueue
from stereocam.tools.conformance.budget import budget

pytestmark = pytest.mark.sim_only("pulls the simulated unit's USB plug")


def _streaming(serial: str, seed: int, gain: int = 35, **options):
    """(sim, its USB handle, a Camera on it) with the unit configured (320x240, 8 fps, ``gain``) and
    streaming; ``options``: stereocam.open's."""
    sim = SimulatedCamera(serial=serial, seed=seed)
    handle = simusb.plug(sim)
    cam = stereocam.open(f"usb://?serial={serial}", timeout=1.0, **options)
    try:
        cam.configure(width=320, height=240, num_disparities=32, block_size=11, fps=8, gain=gain)
        cam.start()
    except BaseException:
        cam.close()
        handle.unplug()
        raise
    return sim, handle, cam


def test_usb_unplug_replug_reconnect_reapplies_config_and_resumes():
    sim, handle, cam = _streaming("RECON-1", 51)
    try:
        before = cam.get_frame(timeout=30)
        handle.unplug()
        with pytest.raises(stereocam.DisconnectedError):
            for _ in range(50):
                cam.get_frame(timeout=1.0)
        sim.close()
        rebooted = SimulatedCamera(serial="RECON-1", seed=51)  # the unit comes back after a power cycle
        assert rebooted.config.snapshot()["fps"] == 30  # with its defaults
        handle = simusb.plug(rebooted)
        cam.reconnect(timeout=5.0)
        cfg = cam.config()
        assert (cfg["fps"], cfg["gain"], cfg["width"], cfg["num_disparities"]) == (8, 35, 320, 32)
        after = cam.get_frame(timeout=30)  # streaming resumed without a start() from the user
        assert after.left.shape == before.left.shape == (240, 320) and after.gain == 35
    finally:
        cam.close()
        handle.unplug()


def test_a_status_during_reconnect_waits_until_the_configuration_is_back(monkeypatch):
    """The watchdog rule (a STATUS of a unit not streaming while the user wants a stream: START)
    must not act between reconnect's STOP and its SET_CONFIG: the unit refuses a format change while
    streaming (BAD_STATE), and that refusal reached get_frame under auto_reconnect."""
    import threading

    from stereocam.protocol import messages as m

    sim, handle, cam = _streaming("RECON-4", 54)
    try:
        cam.get_frame(timeout=30)
        handle.unplug()
        sim.close()
        handle = simusb.plug(SimulatedCamera(serial="RECON-4", seed=54))
        real = cam.request
        acted: list[threading.Thread] = []

        def heartbeat_after_stop(msg, timeout=None):
            reply = real(msg, timeout)
            if isinstance(msg, m.Stop) and not acted:  # a heartbeat's STATUS comes in now
                status = cam.status()
                assert not status.streaming
                t = threading.Thread(target=cam._on_status, args=(status, time.monotonic()), daemon=True)
                acted.append(t)
                t.start()
                t.join(1.0)  # the rule acts at once, unless it waits for the reconnect to finish
            return reply

        monkeypatch.setattr(cam, "request", heartbeat_after_stop)
        cam.reconnect(timeout=5.0)
        acted[0].join(10)
        assert not acted[0].is_alive()
        cfg = cam.config()
        assert (cfg["fps"], cfg["gain"], cfg["width"]) == (8, 35, 320)
        assert cam.get_frame(timeout=30).left.shape == (240, 320) and cam.stream_restarts == 0
    finally:
        monkeypatch.undo()
        cam.close()
        handle.unplug()


def test_reconnect_gives_up_with_a_disconnect_error():
    sim = SimulatedCamera(serial="RECON-2", seed=52)
    handle = simusb.plug(sim)
    cam = stereocam.open("usb://?serial=RECON-2", timeout=1.0)
    handle.unplug()
    sim.close()
    with pytest.raises(stereocam.DisconnectedError, match="RECON-2"):
        cam.reconnect(timeout=0.5)
    cam.close()


def test_auto_reconnect_rides_through_an_unplug():
    import threading

    sim, handle, cam = _streaming("RECON-3", 53, gain=20, auto_reconnect=True)
    handles = [handle]
    try:
        first = cam.get_frame(timeout=30)

        def power_cycle():
            handles[0].unplug()
            sim.close()
            threading.Event().wait(0.5)
            # the unit comes back facing another scene, so that its frames are told apart by what
            # they show: not by their sequence numbers, which restart but may skip past the few the
            # first unit sent before the cable was pulled
            handles.append(simusb.plug(SimulatedCamera(serial="RECON-3", seed=53, scene="wall")))

        threading.Thread(target=power_cycle).start()
        # frames until one of the rebooted unit (queued frames of the first unit come first; a busy
        # host may deliver many), then a few more; no DisconnectedError reaches us
        seen, deadline = 0, time.monotonic() + budget(30)
        while True:
            frame = cam.get_frame(timeout=15)
            if np.abs(frame.left.astype(int) - first.left).mean() > 25:  # lab: 7 apart, wall: 44
                break
            seen += 1
            assert time.monotonic() < deadline, f"no frame of the rebooted unit after {seen} frames"
        frames = [cam.get_frame(timeout=15) for _ in range(3)]
        assert frames[-1].gain == 20 and frames[-1].left.shape == (240, 320)
        assert frames[-1].sequence > frame.sequence and cam.config()["fps"] == 8
    finally:
        cam.close()
        handles[-1].unplug()


@contextlib.contextmanager
def _plugged(serial: str, seed: int):
    """A Camera on a simulated unit plugged in over USB; closed, unplugged and ended afterwards."""
    sim = SimulatedCamera(serial=serial, seed=seed)
    handle = simusb.plug(sim)
    try:
        cam = stereocam.open(f"usb://?serial={serial}", timeout=1.0)
        try:
            yield cam
        finally:
            cam.close()
    finally:
        handle.unplug()
        sim.close()


def test_a_reconnect_asked_for_on_a_healthy_link_says_so_and_not_link_lost(caplog):
    with _plugged("RECON-9", 59) as cam:
        with caplog.at_level("INFO", logger="stereocam"):
            cam.reconnect(timeout=budget(10))
        assert "the link was up" in caplog.text and "link lost" not in caplog.text
        assert cam.info().serial == "RECON-9"


def test_a_listener_added_after_close_is_refused():
    with _plugged("RECON-8", 58) as cam:
        cam.close()
        with pytest.raises(stereocam.TransportError, match="camera closed"):
            cam.add_listener(FrameQueue("late"))
