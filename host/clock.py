"""Device clock → host clock, from time-sync round trips (as librealsense does it, with drift).

Each round trip gives (host send, device time, host receive). The device read its clock somewhere
in between; the midpoint is the estimate and half the round trip bounds its error, so short round
trips are worth far more than long ones (a reply queued behind a frame can take milliseconds). The
map keeps samples spread over the last two minutes, the shorter round trip winning wherever two
crowd together, and fits host = a + b·device through them weighted by 1/rtt² (offset and drift).
The drift has a prior (a crystal's rate error is tens of ppm, SPEC §10): a slope is believed as far
as the round trips measure it, so one burst answered late by a busy device cannot tilt the map.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

from stereocam.protocol.messages import CLOCK_DRIFT_MAX, CLOCK_DRIFT_TYPICAL
from .transports.base import Transport

KEEP = 32
WINDOW_US = 120_000_000  # older samples are forgotten: a crystal's drift wanders with temperature
DRIFT_PRIOR_SIGMA = 2 * CLOCK_DRIFT_TYPICAL  # the drift's prior: N(0, this²), room for a poorer crystal
RTT_FLOOR = 20e-6  # no sample is trusted as more exact than this (s)


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


@dataclass(frozen=True)
class MapError:
    """How far the map is to be trusted, in seconds.

    ``residual`` is the scatter of the trusted samples about the fitted line (weighted RMS);
    ``bias_bound`` is half the best round trip, the most an asymmetric link (slower one way than
    the other) can shift the whole line without any sample showing it. ``sigma`` combines both
    (the bias taken as uniform within its bound)."""

    residual: float
    bias_bound: float
    samples: int
    span_s: float

    @property
    def sigma(self) -> float:
        return math.hypot(self.residual, self.bias_bound / math.sqrt(3))


class ClockMap:
    """Maps device microseconds to host ``time.monotonic()`` seconds.

    Written by the threads taking sync samples (one at a time), read by the threads stamping
    frames: the fit is published as one tuple, so a reader never sees half of an update.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.samples: list[SyncSample] = []
        self._fit: tuple[float, float, int, MapError] | None = None  # (host s at ref, s per µs, ref µs, error)

    def reset(self) -> None:
        """Forget everything (the device may have rebooted: its clock starts over)."""
        with self._lock:
            self.samples = []
            self._fit = None

    def add(self, sample: SyncSample) -> None:
        with self._lock:
            samples = sorted(self.samples + [sample], key=lambda s: s.device_us)
            newest = samples[-1].device_us
            samples = [s for s in samples[:-2] if newest - s.device_us <= WINDOW_US] + samples[-2:]
            while len(samples) > KEEP:  # thin where samples crowd: of the closest two, keep the shorter trip
                i = min(range(len(samples) - 1), key=lambda j: samples[j + 1].device_us - samples[j].device_us)
                del samples[i if samples[i].rtt > samples[i + 1].rtt else i + 1]
            self.samples = samples
            self._fit = _fit(samples)

    def to_host(self, device_us: int) -> float:
        fit = self._fit
        if fit is None:
            return float("nan")
        a, b, ref, _ = fit
        return a + b * (device_us - ref)

    def error(self) -> MapError:
        """The current error estimate (NaN until the first sample)."""
        fit = self._fit
        return fit[3] if fit is not None else MapError(math.nan, math.nan, 0, 0.0)

    @property
    def drift(self) -> float:
        """The fitted device-clock rate error (device µs per host µs − 1; 0 until fitted)."""
        fit = self._fit
        return 1e-6 / fit[1] - 1.0 if fit is not None else 0.0


def _fit(samples: list[SyncSample]) -> tuple[float, float, int, MapError]:
    """Least squares of host midpoint over device time with a Gaussian prior on the drift.

    A midpoint is off by at most half its round trip, uniformly: variance rtt²/12. The slope is
    the posterior mean: what the samples show, pulled toward zero drift by as much as they leave
    it unmeasured (a short span or long trips), and never beyond what a device may do."""
    best = min(samples, key=lambda s: s.rtt)
    ref = best.device_us
    xs = [s.device_us - ref for s in samples]
    ys = [s.host_mid for s in samples]
    ws = [12.0 / max(s.rtt, RTT_FLOOR) ** 2 for s in samples]
    sw = sum(ws)
    mx = sum(w * x for w, x in zip(ws, xs)) / sw
    my = sum(w * y for w, y in zip(ws, ys)) / sw
    sxx = sum(w * (x - mx) ** 2 for w, x in zip(ws, xs))
    sxy = sum(w * (x - mx) * (y - my) for w, x, y in zip(ws, xs, ys))
    nominal, prior_w = 1e-6, 1.0 / (1e-6 * DRIFT_PRIOR_SIGMA) ** 2  # s per device µs, and its weight
    b = (sxy + prior_w * nominal) / (sxx + prior_w)
    b = min(max(b, nominal * (1 - CLOCK_DRIFT_MAX)), nominal * (1 + CLOCK_DRIFT_MAX))
    a = my - b * mx
    resid = math.sqrt(sum(w * (y - a - b * x) ** 2 for w, x, y in zip(ws, xs, ys)) / sw)
    span = max(xs) - min(xs)
    return a, b, ref, MapError(resid, best.rtt / 2, len(samples), span / 1e6)


class ArrivalStamp(Transport):
    """A transport that notes when each read brought bytes (``last``, host monotonic).

    A time-sync reply arrived no later than the read that carried it, however long the requesting
    thread then takes to be woken: the receive side of a round trip is timed there, at the lowest
    layer the host has, so thread hand-offs do not lengthen the trip or skew its midpoint."""

    def __init__(self, inner: Transport):
        self.inner = inner
        self.url = inner.url
        self.last = -math.inf

    def write(self, data: bytes) -> None:
        self.inner.write(data)

    def read(self, max_bytes: int, timeout: float) -> bytes:
        data = self.inner.read(max_bytes, timeout)
        if data:
            self.last = time.monotonic()
        return data

    def close(self) -> None:
        self.inner.close()

    def ended(self) -> str | None:
        return self.inner.ended()

    def __getattr__(self, name: str):  # the wrapped transport's own attributes (sim, port, ...)
        return getattr(self.inner, name)
