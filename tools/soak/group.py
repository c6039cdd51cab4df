"""The lying-head stage of ``stereocam soak`` (issue 22): a ``CameraGroup`` of simulated heads on one
trigger line, one head adding a huge offset to every trigger id it latches, each offset in turn.

Counted: sets received, the liar's refused frames (the matcher must name it), pulses skipped,
the slowest ``get_set``, crashes (any error but a timeout), hangs (no set within ``hang_s``
while the honest heads stream) and the process's peak resident memory before and after.
"""
from __future__ import annotations

import time

import stereocam
from stereocam.device_sim import SimulatedCamera, TriggerLine
from stereocam.device_sim.trigger import TriggerMaster

from .parts import Report, peak_memory_mib, reset_peak_memory, resident_mib

JUMPS = (10**6, 10**7, 2**31, 2**32 - 7)  # the offsets the lying head adds (ids are 32-bit on the wire)
HEADS = 3
FPS = 20
SMALL = dict(width=160, height=120, outputs=int(stereocam.Output.LEFT))
MEMORY_GOAL_MB = 256  # peak-memory growth over the stage that fails the soak


def lying_head_group(seconds: float, hang_s: float = 5.0, seed: int = 0) -> Report:
    """``seconds`` of group streaming, split over the JUMPS, with head 1 lying about trigger ids."""
    rep = Report("lying-head group")
    line = TriggerLine()
    sims = [SimulatedCamera(serial=f"LIAR{seed}-{i}", seed=seed + i, trigger_line=line) for i in range(HEADS)]
    liar = sims[1]
    reset_peak_memory()  # this stage's peak, not the process's history
    before = resident_mib()
    slowest = 0.0
    sets = 0
    try:
        with stereocam.CameraGroup([f"sim://?serial={s.serial}" for s in sims], config=SMALL, master=None,
                                   settle=0.2, deadline=0.3) as group, TriggerMaster(line, FPS):
            for jump in JUMPS:
                liar.trigger_input.id_offset = jump
                end = time.monotonic() + seconds / len(JUMPS)
                while time.monotonic() < end:
                    rep.inputs += 1
                    t0 = time.monotonic()
                    try:
                        group.get_set(timeout=hang_s)
                        sets += 1
                    except stereocam.CameraTimeoutError:
                        rep.hangs += 1
                    except stereocam.StereoCamError:
                        rep.crashes += 1
                        break
                    slowest = max(slowest, time.monotonic() - t0)
            stats = group.stats
    except (stereocam.StereoCamError, MemoryError, OverflowError):
        rep.crashes += 1
        stats = None
    finally:
        for s in sims:
            s.close()
    after = peak_memory_mib()
    rep.figures.update({
        "jumps": ", ".join(str(j) for j in JUMPS),
        "sets": sets,
        "liar named": ", ".join(f"{n} ({c} frames refused)" for n, c in stats.implausible.items()) if stats else "-",
        "pulses skipped": stats.skipped if stats else "-",
        "slowest get_set s": round(slowest, 3),
        "peak memory MB": f"{after:.0f} (growth {after - before:.0f}, limit {MEMORY_GOAL_MB})",
    })
    if stats is None or set(stats.implausible) != {liar.serial}:
        rep.figures["liar named"] = f"NO ({rep.figures['liar named']})"
    if after - before > MEMORY_GOAL_MB:
        rep.figures["memory goal"] = "NOT MET"
    return rep
