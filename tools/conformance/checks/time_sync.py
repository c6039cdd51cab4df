"""Time synchronisation (SPEC §10): the device clock is monotonic and runs at 1 s/s within 1000 ppm."""
from __future__ import annotations

import time

from stereocam.protocol import messages as m

from ..context import Context
from ..registry import check
from ..results import expect

SPAN_S = 2.5
SAMPLES = 26
ENDS = 6  # the best-rtt sample of the first and of the last few bound the rate


@check("time.sync", "R-4.8-1", "R-10-1")
def time_sync(ctx: Context) -> str:
    """TIME_SYNC round trips over a few seconds: device time rises strictly, and its rate against
    the host's monotonic clock, bounded by each sample's round trip, admits 1 +- 1000 ppm."""
    ctx.require(m.Capability.TIME_SYNC)
    samples = []
    for _ in range(SAMPLES):
        t0 = time.monotonic()
        r = ctx.s.call(m.TimeSync())
        t1 = time.monotonic()
        assert isinstance(r, m.Time)
        samples.append((t0, r.device_time_us, t1))
        time.sleep(max(0.0, t0 + SPAN_S / (SAMPLES - 1) - time.monotonic()))
    devs = [d for _, d, _ in samples]
    expect(all(b > a for a, b in zip(devs, devs[1:])), "device time did not rise strictly between TIME replies")
    first = min(samples[:ENDS], key=lambda s: s[2] - s[0])
    last = min(samples[-ENDS:], key=lambda s: s[2] - s[0])
    dev_span = (last[1] - first[1]) / 1e6
    slowest = dev_span / (last[2] - first[0])  # the longest host interval the two readings allow
    fastest = dev_span / (last[0] - first[2])
    expect(fastest >= 1 - m.CLOCK_DRIFT_MAX and slowest <= 1 + m.CLOCK_DRIFT_MAX,
           f"device clock rate between {(slowest - 1) * 1e6:+.0f} and {(fastest - 1) * 1e6:+.0f} ppm over "
           f"{dev_span:.2f} s, outside +-{m.CLOCK_DRIFT_MAX * 1e6:.0f} ppm")
    mid = (slowest + fastest) / 2
    return (f"{SAMPLES} samples over {dev_span:.2f} s: rate {(mid - 1) * 1e6:+.0f} ppm "
            f"(bounds {(slowest - 1) * 1e6:+.0f}..{(fastest - 1) * 1e6:+.0f})")
