"""``stereocam demo --heads N``: N simulated heads on one trigger line, streamed as matched sets.

The group makes the first head the trigger master (``trigger_output``: it drives the line at the
frame rate, timed by its own crystal); every head is a separate unit with its own clock. Prints each head's clock-map error estimate, the spread of the
capture times within the sets, the sets that lacked a head's frame (which head, which trigger),
and saves the last complete set's images to ./out/.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

import stereocam
from stereocam.device_sim import SimulatedCamera, TriggerLine
from stereocam.frame_sets import MatchedSet

from stereocam.tools.camera.capture import save_frame

SHOW_MISSING = 10  # incomplete sets printed one by one; the rest are counted


def run(heads: int, seconds: float, fps: int, seed: int, out: Path, settings: dict[str, int] | None = None) -> int:
    line = TriggerLine()
    sims = [SimulatedCamera(serial=f"HEAD{i + 1}", seed=seed + i, trigger_line=line) for i in range(heads)]
    try:
        config = {**dict(width=320, height=240, num_disparities=32, block_size=11, fps=fps),  # N heads share this machine
                  **(settings or {})}
        with stereocam.CameraGroup([f"sim://?serial={s.serial}" for s in sims], config=config, master=0,
                                   timeout=30.0) as group:
            print(f"{heads} heads on one trigger line at {fps} fps, {sims[0].serial} drives it: "
                  + ", ".join(f"{s.serial} drift {s.clock.drift * 1e6:+.1f} ppm" for s in sims))
            sets: list[MatchedSet] = []
            last = None
            t0 = time.monotonic()
            while not sets or time.monotonic() - t0 < seconds:  # at least one set, however short
                s = group.get_set()
                sets.append(s)
                if s.complete:
                    last = s
                elif group.stats.incomplete <= SHOW_MISSING:
                    print(f"  trigger {s.trigger_id}: no frame from {', '.join(s.missing)}")
            errors = group.clock_errors()
            stats = group.stats
    finally:
        for sim in sims:
            sim.close()
    for name, e in errors.items():
        print(f"  {name}: clock map error estimate {e.sigma * 1e6:.0f} µs ({e.samples} sync samples over {e.span_s:.1f} s)")
    skew = np.array([s.skew for s in sets if s.complete]) * 1e6
    if len(skew):
        print(f"summary: sets={len(sets)} complete={stats.complete} incomplete={stats.incomplete} "
              f"skew p50={np.percentile(skew, 50):.0f} µs p99={np.percentile(skew, 99):.0f} µs max={skew.max():.0f} µs")
    if last is not None:
        for name, frame in last.frames.items():
            paths = save_frame(frame, out, f"demo_{name}_t{last.trigger_id}")
            print(f"wrote {', '.join(str(p) for p in paths.values())}")
    return 0

