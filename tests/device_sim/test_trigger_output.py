"""A unit's trigger output (SPEC §5.1 ``trigger_output``): the master pulses the line at its frame
rate exactly while its stream runs, captures on its own pulses like every head on the line, and a
build without the capability refuses the value, changing nothing."""
from __future__ import annotations

import dataclasses

import pytest

import stereocam
from stereocam.device_sim import SimulatedCamera, TriggerLine
from stereocam.device_sim.boot.factory import DEV_SIGNING_KEY
from stereocam.protocol import messages as m
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.firmware_image import build_image
from tests.support.firmware import build
from tests.support.waiting import stays, wait_until

from .test_firmware import open_sim

pytestmark = pytest.mark.sim_only("watches the simulated line and the unit's output driver")

SMALL = dict(width=160, height=120, outputs=int(stereocam.Output.LEFT))
MASTER = dict(trigger_mode=int(stereocam.TriggerMode.EXTERNAL), trigger_output=1)


def frames(cam, n: int) -> list:
    return [cam.get_frame(timeout=20) for _ in range(n)]


def test_the_master_captures_on_its_own_pulses_at_its_rate_and_every_head_gets_the_same_ids():
    line = TriggerLine()
    sims = [SimulatedCamera(seed=s, trigger_line=line) for s in (14, 4)]  # +50 and -46 ppm crystals
    master, other = (open_sim(sim) for sim in sims)
    try:
        other.configure(**SMALL, trigger_mode=int(stereocam.TriggerMode.EXTERNAL))
        other.start()
        master.configure(**SMALL, **MASTER, fps=20)
        assert line.pulses == 0  # configured, not yet streaming: the line stays low
        master.start()
        got = frames(master, 6)
        heard = frames(other, 6)
        assert [f.trigger_id for f in got] == [f.trigger_id for f in heard] == list(range(1, 7))
        period_us = [b.device_time_us - a.device_time_us for a, b in zip(got, got[1:])]
        assert all(abs(p - 50_000) < 500 for p in period_us)  # 20 fps on its own crystal (trigger jitter: µs)
        assert sims[0].trigger_output.driving and not sims[1].trigger_output.driving
        master.stop()
        stopped_at = line.pulses
        assert not sims[0].trigger_output.driving
        assert stays(lambda: line.pulses == stopped_at, 0.3)  # six periods: a driven line would pulse again
    finally:
        for cam in (master, other):
            cam.close()
        for sim in sims:
            sim.close()


STOPS = {
    "watchdog": lambda sim, cam: None,  # no heartbeat: the watchdog stops the stream at 400 ms
    "reboot": lambda sim, cam: sim.reboot(),
    "power cut": lambda sim, cam: sim.power_cut(),
    "link lost": lambda sim, cam: sim.detach(),
}


@pytest.mark.parametrize("how", list(STOPS))
def test_the_output_falls_silent_whenever_the_stream_stops(how):
    sim = SimulatedCamera(seed=22)  # unwired: its own input still hears its output
    with open_sim(sim, heartbeat_interval=3600) as cam:
        cam.configure(**SMALL, **MASTER, fps=20, heartbeat_timeout_ms=400)
        cam.start()
        assert cam.get_frame(timeout=20).trigger_id >= 1 and sim.trigger_output.driving
        STOPS[how](sim, cam)
        wait_until(lambda: not sim.engine.streaming and not sim.trigger_output.driving, what="the output released")
        pulses = sim.trigger_line.pulses
        assert stays(lambda: sim.trigger_line.pulses == pulses, 0.2)


@pytest.mark.parametrize("update, blamed", [
    (dict(trigger_output=1), "trigger_output"),  # from free run
    (dict(trigger_output=1, trigger_mode=int(stereocam.TriggerMode.SOFTWARE)), "trigger_output"),
    (dict(**MASTER, exposure_us=60_000), "exposure_us"),  # longer than the 20 fps period it pulses at
])
def test_a_master_the_rules_forbid_is_refused_and_nothing_changes(update, blamed):
    with open_sim(SimulatedCamera(seed=23)) as cam:
        cam.configure(fps=20)
        before = cam.config()
        with pytest.raises(stereocam.DeviceError) as refused:
            cam.configure(**update)
        assert refused.value.code == ErrorCode.OUT_OF_RANGE and refused.value.param == blamed
        assert cam.config() == before
        with pytest.raises(stereocam.ConfigError) as predicted:  # the host's check says the same
            cam.check_config(**update)
        assert predicted.value.param == blamed


def test_a_build_without_the_capability_refuses_the_output_and_keeps_its_configuration():
    sim = SimulatedCamera(serial="NO-OUT", seed=24)
    cam = stereocam.open("sim://?serial=NO-OUT", timeout=2.0)
    try:
        b = build("1.3.0")
        no_output = dataclasses.replace(b, capabilities=b.capabilities & ~m.Capability.TRIGGER_OUTPUT)
        cam.update_firmware(build_image(no_output, DEV_SIGNING_KEY, target="STOC-SIM"))
        assert not cam.info().capabilities & m.Capability.TRIGGER_OUTPUT
        cam.configure(trigger_mode=int(stereocam.TriggerMode.EXTERNAL))
        before = cam.config()
        with pytest.raises(stereocam.DeviceError) as refused:
            cam.configure(trigger_output=1)
        assert refused.value.code == ErrorCode.OUT_OF_RANGE and "TRIGGER_OUTPUT" in str(refused.value)
        assert cam.config() == before
        with pytest.raises(stereocam.ConfigError, match="TRIGGER_OUTPUT"):
            cam.check_config(trigger_output=1)
    finally:
        cam.close()
        sim.close()
