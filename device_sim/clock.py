"""The device's free-running microsecond clock: its own epoch, a crystal that drifts, read with jitter."""
from __future__ import annotations

import random
import time

READ_JITTER_US = 1.0  # sigma of one reading of the counter (latch and interrupt latency)


class DeviceClock:
    """Device time in µs = (host monotonic − boot) · (1 + drift) + epoch, plus a little read jitter.

    Each unit has its own crystal (a drift within ±50 ppm, fixed per unit) and its own boot time
    (``epoch_us``: the counter's value when the simulator started), drawn from its seed, so the
    host's clock mapping has real work to do. ``host_monotonic`` inverts the jitter-free mapping
    for ground-truth checks.
    """

    def __init__(self, seed: int = 0, jitter_us: float = READ_JITTER_US):
        rnd = random.Random(seed ^ 0xC10C)
        self.drift = rnd.uniform(-50e-6, 50e-6)
        self.epoch_us = rnd.randrange(0, 3_600_000_000)
        self.boot = time.monotonic()
        self.jitter_us = jitter_us
        self._noise = random.Random(seed ^ 0x7177E6)

    def now_us(self) -> int:
        return self.at(time.monotonic())

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
        return int((time.monotonic() - self.boot) * (1.0 + self.drift) * 1e6)
