"""The device side's time base: a fake clock moves only when told, and wakes its waiters then."""
from __future__ import annotations

import threading

import pytest

from stereocam.device_sim.clock import ClockError, DeviceClock, FakeClock
from stereocam.device_sim.trigger import TriggerLine, TriggerMaster
from tests.support.hangs import returns_within
from tests.support.waiting import stays, wait_until


def test_a_fake_clock_moves_only_when_advanced():
    clock = FakeClock(start=10.0)
    assert clock.monotonic() == 10.0
    clock.advance(0.25)
    assert clock.monotonic() == 10.25
    with pytest.raises(ClockError):
        clock.advance(-0.1)


def test_a_waiter_wakes_when_its_deadline_passes():
    clock, never = FakeClock(), threading.Event()
    woke = threading.Event()
    t = threading.Thread(target=lambda: (clock.wait(never, 1.0), woke.set()), daemon=True)
    t.start()
    clock.advance(0.9)
    assert not woke.wait(0.05)  # 100 ms of fake time still to go, however long it really waits
    clock.advance(0.1)
    wait_until(woke.is_set, what="the waiter wakes at its deadline")


def test_a_set_event_ends_a_wait_without_time_passing():
    clock, event = FakeClock(), threading.Event()
    event.set()
    assert returns_within(2.0, clock.wait, event, 3600.0) is True
    assert returns_within(2.0, clock.wait, threading.Event(), 0.0) is False


def test_the_device_counter_runs_on_its_time_base():
    clock = FakeClock()
    dev = DeviceClock(seed=3, jitter_us=0, timebase=clock)
    t0 = dev.now_us()
    clock.advance(2.0)
    assert dev.now_us() - t0 == pytest.approx(2e6 * (1 + dev.drift), abs=1)
    assert dev.uptime_us() == pytest.approx(2e6 * (1 + dev.drift), abs=1)


def test_a_trigger_master_pulses_once_per_period_of_its_clock():
    clock, line = FakeClock(), TriggerLine()
    edges: list[tuple[int, float]] = []
    line.attach(lambda tid, instant: edges.append((tid, instant)))
    start = clock.monotonic()
    with TriggerMaster(line, 10.0, timebase=clock):
        assert stays(lambda: not edges, 0.1)  # no time has passed: no edge
        for n in range(1, 4):
            clock.advance(0.1)
            wait_until(lambda n=n: len(edges) >= n, what=f"edge {n}")
    assert [tid for tid, _ in edges[:3]] == [1, 2, 3]
    assert [round(at - start, 6) for _, at in edges[:3]] == [0.1, 0.2, 0.3]
