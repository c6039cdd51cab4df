"""The trigger line: per-unit latency, pulses carrying their edge instant, the machine-wide line
(Unix datagram sockets), the master's rate on its own crystal."""
from __future__ import annotations

import os
import socket
import threading
import time

import pytest

import stereocam
from stereocam.device_sim import TriggerLine
from stereocam.device_sim.clock import DeviceClock
from stereocam.device_sim.replay import ReplayClock
from stereocam.device_sim.shared_line import SharedTriggerLine
from stereocam.device_sim.trigger import LATENCY_RANGE_S, TriggerInput, TriggerMaster
from tests.support.waiting import wait_until


class Heard:
    def __init__(self) -> None:
        self.pulses: list[tuple[int, float]] = []
        self.event = threading.Event()

    def __call__(self, tid: int, instant: float) -> None:
        self.pulses.append((tid, instant))
        self.event.set()

    def wait(self, n: int, timeout: float = 5.0) -> None:
        wait_until(lambda: len(self.pulses) >= n, timeout, f"{n} pulses heard")


def test_each_unit_exposes_its_own_latency_after_the_edge():
    heard = [Heard() for _ in range(3)]
    inputs = [TriggerInput(seed, h) for seed, h in zip((1, 2, 3), heard)]
    line = TriggerLine()
    for i in inputs:
        line.attach(i.on_pulse)
    t = time.monotonic() - 1.0  # an edge a second ago: a late delivery still exposes at its instant
    tid = line.pulse(t)
    lat = [h.pulses[0][1] - t for h in heard]
    assert [h.pulses[0][0] for h in heard] == [tid] * 3
    assert all(LATENCY_RANGE_S[0] - 2e-6 < x < LATENCY_RANGE_S[1] + 2e-6 for x in lat)
    assert len({round(x * 1e7) for x in lat}) == 3  # three units, three latencies
    assert [i.latency_s for i in inputs] == [TriggerInput(s, Heard()).latency_s for s in (1, 2, 3)]  # from the seed


def test_shared_line_reaches_every_listener_with_one_id_and_instant():
    name = f"t{os.getpid()}-{time.monotonic_ns()}"
    a, b, driver = SharedTriggerLine(name), SharedTriggerLine(name), SharedTriggerLine(name)
    ha, hb = Heard(), Heard()
    a.attach(ha)
    b.attach(hb)
    try:
        ids = [driver.pulse(100.0 + k) for k in range(3)]
        ha.wait(3)
        hb.wait(3)
        assert ids == [1, 2, 3] and driver.pulses == 3  # the line's own pulse numbers
        assert ha.pulses == hb.pulses == [(1, 100.0), (2, 101.0), (3, 102.0)]
        assert b.pulse() == 4  # whoever drives it, the numbering goes on
    finally:
        for line in (a, b, driver):
            line.close()
    assert not (a.dir).exists()  # the last one tidies up


def test_shared_line_forgets_a_listener_whose_process_is_gone():
    name = f"t{os.getpid()}-{time.monotonic_ns()}"
    line = SharedTriggerLine(name)
    dead = line.dir / "999999-0.sock"
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    s.bind(str(dead))
    s.close()  # bound, then its process died without tidying
    try:
        line.pulse()
        assert not dead.exists()
    finally:
        line.close()


def test_bad_line_name_is_a_config_error():
    with pytest.raises(stereocam.ConfigError, match="trigger line name"):
        SharedTriggerLine("../etc")


def test_master_rate_is_counted_on_its_own_crystal():
    clock = DeviceClock(14)  # +50 ppm: its second is shorter on the host's clock
    line = TriggerLine()
    heard = Heard()
    line.attach(heard)
    with TriggerMaster(line, 50, clock) as master:
        heard.wait(5)
    assert master.period == pytest.approx(0.02 / (1 + clock.drift), rel=1e-9)
    gaps = [b[1] - a[1] for a, b in zip(heard.pulses, heard.pulses[1:])]
    assert all(g == pytest.approx(master.period, abs=1e-9) for g in gaps)  # scheduled edges, not wake-ups
    assert [t for t, _ in heard.pulses] == list(range(1, len(heard.pulses) + 1))


def test_a_replayed_unit_masters_the_line_at_its_nominal_rate():
    """A replay's clock counts at the time base's rate: a replayed unit driving the line pulses at
    exactly its fps (its clock gives everything a unit's clock gives, host_period included)."""
    line = TriggerLine()
    heard = Heard()
    line.attach(heard)
    with TriggerMaster(line, 50, ReplayClock(start_us=123_456)) as master:
        heard.wait(3)
    assert master.period == 0.02
    assert len(heard.pulses) >= 3
