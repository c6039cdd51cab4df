"""The device's free-running microsecond clock: its own epoch, and a crystal that drifts."""
from __future__ import annotations

import random
import time


class DeviceClock:
    """Device time in µs = (host monotonic − boot) · (1 + drift) + epoch offset.

    Each unit has its own drift (±50 ppm) and epoch, drawn from its seed, so the host's clock
    mapping has real work to do. ``host_monotonic`` inverts the mapping for ground-truth checks.
    """

    def __init__(self, seed: int = 0):
        rnd = random.Random(seed ^ 0xC10C)
        self.drift = rnd.uniform(-50e-6, 50e-6)
        self.epoch_us = rnd.randrange(0, 3_600_000_000)
        self.boot = time.monotonic()

    def now_us(self) -> int:
        return self.at(time.monotonic())

    def at(self, host_monotonic: float) -> int:
        return int((host_monotonic - self.boot) * (1.0 + self.drift) * 1e6) + self.epoch_us

    def host_monotonic(self, device_us: int) -> float:
        return self.boot + (device_us - self.epoch_us) / 1e6 / (1.0 + self.drift)

    def uptime_us(self) -> int:
        return int((time.monotonic() - self.boot) * 1e6)
