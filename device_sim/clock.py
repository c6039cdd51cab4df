"""Time on the device side: the host-monotonic time base every device part reads and waits on
(``Clock``: ``RealClock`` by default, ``FakeClock`` in tests), and the device's free-running
microsecond counter built on it (``DeviceClock``: its own epoch, a crystal that drifts, read with
jitter; ``UnitClock``: what the firmware reads of it, which a replay's clock also gives)."""
from __future__ import annotations

import random
import threading
import time
from typing import Protocol

from stereocam.protocol.errors import StereoCamError

READ_JITTER_US = 1.0  # sigma of one reading of the counter (latch and interrupt latency)
FAKE_POLL_S = 0.005
"""How often (real seconds) a FakeClock waiter looks at an event set by a thread that does not
advance the clock (``close`` from another thread)."""
FAKE_RESOLUTION_S = 1e-9
"""A FakeClock deadline this close counts as reached: ``now + (instant - now)`` need not round back
to ``instant``, and a waiter for exactly the instant a test advanced to must wake."""


class ClockError(StereoCamError):
    """A time base used wrongly (a fake clock moved backwards)."""


class Clock(Protocol):
    """The host-monotonic time base of the device side: read it, and wait on it."""

    def monotonic(self) -> float:
        """Seconds, never decreasing."""
        ...

    def wait(self, event: threading.Event, timeout: float) -> bool:
        """Block until ``event`` is set (True) or ``timeout`` seconds of this clock passed (False)."""
        ...

    def sleep(self, seconds: float) -> None:
        """Block for ``seconds`` of this clock."""
        ...


class RealClock:
    """The host's own monotonic clock: what a running simulator uses."""

    def monotonic(self) -> float:
        return time.monotonic()

    def wait(self, event: threading.Event, timeout: float) -> bool:
        return event.wait(max(timeout, 0.0))

    def sleep(self, seconds: float) -> None:
        time.sleep(max(seconds, 0.0))


REAL_CLOCK = RealClock()


class FakeClock:
    """Time that moves only when a test calls ``advance``: waiters whose deadline it passes wake then."""

    def __init__(self, start: float = 1000.0):
        self._now = start
        self._cond = threading.Condition()

    def monotonic(self) -> float:
        with self._cond:
            return self._now

    def advance(self, seconds: float) -> None:
        """Move time forward by ``seconds`` and wake every waiter to look at it."""
        if seconds < 0:
            raise ClockError(f"a clock does not go back ({seconds} s)")
        with self._cond:
            self._now += seconds
            self._cond.notify_all()

    def wait(self, event: threading.Event, timeout: float) -> bool:
        with self._cond:
            deadline = self._now + timeout
            while not event.is_set():
                if self._now >= deadline - FAKE_RESOLUTION_S:
                    return False
                self._cond.wait(FAKE_POLL_S)
        return True

    def sleep(self, seconds: float) -> None:
        self.wait(threading.Event(), seconds)


class DeviceClock:
    """Device time in µs = (host monotonic − boot) · (1 + drift) + epoch, plus a little read jitter.

    Each unit has its own crystal (a drift within ±50 ppm, fixed per unit) and its own boot time
    (``epoch_us``: the counter's value when the simulator started), drawn from its seed, so the
    host's clock mapping has real work to do. ``host_monotonic`` inverts the jitter-free mapping
    for ground-truth checks. ``timebase``: the host-monotonic time the crystal counts on.
    """

    def __init__(self, seed: int = 0, jitter_us: float = READ_JITTER_US, timebase: Clock = REAL_CLOCK):
        rnd = random.Random(seed ^ 0xC10C)
        self.drift = rnd.uniform(-50e-6, 50e-6)
        self.epoch_us = rnd.randrange(0, 3_600_000_000)
        self.timebase = timebase
        self.boot = timebase.monotonic()
        self.jitter_us = jitter_us
        self._noise = random.Random(seed ^ 0x7177E6)

    def now_us(self) -> int:
        return self.at(self.timebase.monotonic())

    def at(self, host_monotonic: float) -> int:
        """The counter as the firmware reads it at that host instant (jitter included)."""
        jitter = self._noise.gauss(0.0, self.jitter_us) if self.jitter_us else 0.0
        return int((host_monotonic - self.boot) * (1.0 + self.drift) * 1e6 + jitter) + self.epoch_us

    def host_monotonic(self, device_us: int) -> float:
        return self.boot + (device_us - self.epoch_us) / 1e6 / (1.0 + self.drift)

    def host_period(self, device_seconds: float) -> float:
        """How long ``device_seconds`` on this crystal last on the host's clock."""
        return device_seconds / (1.0 + self.drift)

    def uptime_us(self) -> int:
        return int((self.timebase.monotonic() - self.boot) * (1.0 + self.drift) * 1e6)


class UnitClock(Protocol):
    """The firmware's microsecond counter as its parts read it: a simulated crystal (``DeviceClock``)
    or the recorded unit's clock of a replay (replay.py ``ReplayClock``)."""

    timebase: Clock
    boot: float  # the host-monotonic instant the counter started from
    epoch_us: int  # the counter's value at ``boot``
    drift: float  # the crystal's rate error against ``timebase`` (1e-6 = 1 ppm)

    def now_us(self) -> int:
        """The counter now."""
        ...

    def at(self, host_monotonic: float) -> int:
        """The counter at that host instant."""
        ...

    def uptime_us(self) -> int:
        """Microseconds since ``boot`` on this counter."""
        ...

    def host_period(self, device_seconds: float) -> float:
        """How long ``device_seconds`` on this counter last on the host's clock."""
        ...
