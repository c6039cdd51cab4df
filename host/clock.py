"""Device clock → host clock, from time-sync round trips (as librealsense does it).

Each round trip gives (host send, device time, host receive). The best estimate of when the
device read its clock is the midpoint, and the shorter the round trip, the tighter the bound, so
the map keeps the lowest-RTT samples and fits host = a + b·device through them (offset + drift).
"""
from __future__ import annotations

from dataclasses import dataclass

KEEP = 32
MAX_DRIFT = 1e-3  # a crystal is within 1000 ppm


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


class ClockMap:
    """Maps device microseconds to host ``time.monotonic()`` seconds.

    Written by the thread taking sync samples, read by the thread stamping frames: the fit is
    published as one tuple, so a reader never sees half of an update.
    """

    def __init__(self) -> None:
        self.samples: list[SyncSample] = []
        self._fit: tuple[float, float, int] | None = None  # (host s at ref, host s per device µs, ref µs)

    def reset(self) -> None:
        """Forget everything (the device may have rebooted: its clock starts over)."""
        self.samples = []
        self._fit = None

    def add(self, sample: SyncSample) -> None:
        samples = sorted(self.samples + [sample], key=lambda s: s.device_us)
        if len(samples) > KEEP:  # drop the worst round trip, keep the time span
            del samples[max(range(1, len(samples) - 1), key=lambda i: samples[i].rtt)]
        self.samples = samples
        self._fit = _fit(samples)

    def to_host(self, device_us: int) -> float:
        fit = self._fit
        if fit is None:
            return float("nan")
        a, b, ref = fit
        return a + b * (device_us - ref)


def _fit(samples: list[SyncSample]) -> tuple[float, float, int]:
    """Line through the better half of the samples (lowest round trips); drift only when the
    samples span enough device time to show it, and never beyond what a crystal can do."""
    good = sorted(samples, key=lambda s: s.rtt)[: max(2, len(samples) // 2)]
    ref = good[0].device_us
    if len(good) < 2 or max(s.device_us for s in good) - min(s.device_us for s in good) < 200_000:
        return good[0].host_mid, 1e-6, ref
    xs = [s.device_us - ref for s in good]
    ys = [s.host_mid for s in good]
    n = len(xs)
    mx, my = sum(xs) / n, sum(ys) / n
    sxx = sum((x - mx) ** 2 for x in xs)
    b = sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx
    b = min(max(b, 1e-6 * (1 - MAX_DRIFT)), 1e-6 * (1 + MAX_DRIFT))
    return my - b * mx, b, ref
