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


def streaming_samples(drift_ppm: float, seconds: int, seed: int = 1) -> tuple[ClockMap, callable]:
    """Sync bursts once a second while frames stream: most replies wait behind frame data (a few ms,
    all on the way back), now and then one finds the link free."""
    rnd = random.Random(seed)
    truth = lambda host_s: int(host_s * (1 + drift_ppm * 1e-6) * 1e6) + 777_000_000  # noqa: E731
    cm = ClockMap()
    for k in range(8):  # at connect, before streaming: short trips
        t0 = 100.0 + k * 1e-3
        cm.add(SyncSample(t0, truth(t0 + 25e-6), t0 + 50e-6))
    for sec in range(1, seconds + 1):
        for j in range(3):
            t0 = 100.0 + sec + j * 0.01
            down = 60e-6 if rnd.random() < 0.4 else rnd.uniform(1e-3, 6e-3)
            cm.add(SyncSample(t0, truth(t0 + 30e-6), t0 + 30e-6 + down))
    return cm, truth


@pytest.mark.parametrize("drift_ppm", [-46.0, 50.0])
def test_drift_is_followed_from_the_short_trips_among_long_ones(drift_ppm):
    cm, truth = streaming_samples(drift_ppm, 40)
    for host_s in (120.0, 140.0, 141.0):  # over 40 s a missed drift would be 2 ms off
        assert abs(cm.to_host(truth(host_s)) - host_s) < 20e-6
    assert cm.drift == pytest.approx(drift_ppm * 1e-6, abs=1e-6)
    assert len(cm.samples) == 32  # thinned where they crowd, the short trip kept:
    assert sum(s.rtt < 1e-3 for s in cm.samples) >= 24  # ~60 % of all samples were long


def test_error_estimate_reports_scatter_and_the_asymmetry_bound():
    assert ClockMap().error().samples == 0 and ClockMap().error().sigma != ClockMap().error().sigma  # NaN
    tight, _ = simulate(20.0, 5_000, n=30, span_s=10.0, seed=3)
    loose = ClockMap()
    rnd = random.Random(4)
    for i in range(30):  # the same clock read through a far noisier link
        t0 = 100.0 + 10.0 * i / 29
        up, down = rnd.expovariate(1 / 0.003), rnd.expovariate(1 / 0.003)
        loose.add(SyncSample(t0, int((t0 + up) * (1 + 20e-6) * 1e6) + 5_000, t0 + up + down))
    et, el = tight.error(), loose.error()
    assert et.bias_bound == min(s.rtt for s in tight.samples) / 2
    assert el.residual > 3 * et.residual and el.sigma > et.sigma > 0
    assert et.samples == 30 and et.span_s == pytest.approx(10.0, rel=0.01)


def test_samples_older_than_the_window_are_forgotten():
    cm, truth = streaming_samples(10.0, 200)
    oldest = min(s.device_us for s in cm.samples)
    assert max(s.device_us for s in cm.samples) - oldest <= 120_000_000
    assert abs(cm.to_host(truth(300.0)) - 300.0) < 20e-6


def test_one_burst_held_up_on_the_way_to_the_device_does_not_tilt_the_map():
    """A busy device answers a whole burst late (each request waits behind a frame being matched,
    so the device reads its clock just before replying): a slope fitted through that burst alone
    would carry its milliseconds of bias to every later frame. A crystal's drift is known to be
    small (SPEC §10); one poorly measured second may not outweigh that."""
    truth = lambda host_s: int(host_s * (1 + 20e-6) * 1e6) + 9_000_000  # noqa: E731
    cm = ClockMap()
    for k in range(8):  # at connect: short trips
        t0 = 100.0 + k * 1e-3
        cm.add(SyncSample(t0, truth(t0 + 25e-6), t0 + 50e-6))
    for j in range(3):  # one second later: every request waited ~5.6 ms on the device's side
        t0 = 101.0 + j * 0.01
        cm.add(SyncSample(t0, truth(t0 + 5.6e-3), t0 + 5.65e-3))
    for host_s in (100.5, 101.0, 103.0):
        assert abs(cm.to_host(truth(host_s)) - host_s) < 300e-6
    assert abs(cm.drift) < 100e-6
