"""Device→host clock mapping from time-sync round trips."""
from __future__ import annotations

import random

import pytest

from stereocam.clock import ClockMap, SyncSample


def simulate(drift_ppm: float, offset_us: int, n: int, span_s: float, seed: int = 0) -> tuple[ClockMap, callable]:
    """A device clock with drift and offset, sampled by round trips with random delays."""
    rnd = random.Random(seed)
    truth = lambda host_s: int(host_s * (1 + drift_ppm * 1e-6) * 1e6) + offset_us  # noqa: E731
    cm = ClockMap()
    for i in range(n):
        t0 = 100.0 + span_s * i / max(n - 1, 1)
        up, down = rnd.expovariate(1 / 0.0003), rnd.expovariate(1 / 0.0003)  # asymmetric, jittery
        cm.add(SyncSample(t0, truth(t0 + up), t0 + up + down))
    return cm, truth


@pytest.mark.parametrize("drift_ppm", [-50.0, 0.0, 40.0])
def test_offset_and_drift_are_recovered(drift_ppm):
    cm, truth = simulate(drift_ppm, 3_600_000_123, n=40, span_s=60.0)
    for host_s in (100.0, 130.0, 160.0, 200.0):  # inside and 40 s beyond the sampled span
        assert abs(cm.to_host(truth(host_s)) - host_s) < 0.0005
    assert len(cm.samples) == 32  # bounded: the worst round trips are dropped


def test_without_drift_fit_a_short_span_maps_the_offset():
    cm, truth = simulate(30.0, 5_000, n=8, span_s=0.05)
    assert abs(cm.to_host(truth(100.02)) - 100.02) < 0.0005


def test_no_samples_no_mapping_and_reset():
    cm = ClockMap()
    assert cm.to_host(123) != cm.to_host(123)  # NaN until synced
    cm.add(SyncSample(1.0, 10, 1.001))
    assert abs(cm.to_host(10) - 1.0005) < 1e-9
    cm.reset()
    assert cm.samples == [] and cm.to_host(10) != cm.to_host(10)
