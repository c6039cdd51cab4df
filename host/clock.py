"""Device clock → host clock, from time-sync round trips (as librealsense does it).

Each round trip gives (host send, device time, host receive). The best estimate of when the
device read its clock is the midpoint, and the shorter the round trip, the tighter the bound, so
the map keeps the lowest-RTT samples and fits host = a + b·device through them (offset + drift).
"""
from __future__ import annotations

from dataclasses import dataclass, field

KEEP = 32


@dataclass(frozen=True)
class SyncSample:
    host_send: float
    device_us: int
    host_recv: float

    @property
    def rtt(self) -> float:
        return self.host_recv - self.host_send

    @property
    def host_mid(self) -> float:
        return 0.5 * (self.host_send + self.host_recv)


@dataclass
class ClockMap:
    """Maps device microseconds to host ``time.monotonic()`` seconds."""

    samples: list[SyncSample] = field(default_factory=list)
    _a: float = 0.0  # host seconds at device_us == _ref
    _b: float = 1e-6  # host seconds per device µs
    _ref: int = 0

    @property
    def ready(self) -> bool:
        return bool(self.samples)

    @property
    def best_rtt(self) -> float:
        return min(s.rtt for s in self.samples)

    def add(self, sample: SyncSample) -> None:
        self.samples.append(sample)
        self.samples.sort(key=lambda s: s.device_us)
        if len(self.samples) > KEEP:  # drop the worst round trip, keep the time span
            worst = max(range(1, len(self.samples) - 1), key=lambda i: self.samples[i].rtt)
            del self.samples[worst]
        self._fit()

    def _fit(self) -> None:
        good = sorted(self.samples, key=lambda s: s.rtt)[: max(2, len(self.samples) // 2)]
        self._ref = good[0].device_us
        if len(good) < 2 or max(s.device_us for s in good) - min(s.device_us for s in good) < 200_000:
            self._a, self._b = good[0].host_mid, 1e-6  # too short a span to see drift
            return
        xs = [s.device_us - self._ref for s in good]
        ys = [s.host_mid for s in good]
        n = len(xs)
        mx, my = sum(xs) / n, sum(ys) / n
        sxx = sum((x - mx) ** 2 for x in xs)
        b = sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx
        self._b = min(max(b, 1e-6 * (1 - 1e-3)), 1e-6 * (1 + 1e-3))  # a crystal is within 1000 ppm
        self._a = my - self._b * mx

    def to_host(self, device_us: int) -> float:
        if not self.samples:
            return float("nan")
        return self._a + self._b * (device_us - self._ref)
