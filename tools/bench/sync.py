"""``stereocam bench sync``: several heads on one trigger line, how well their capture times agree.

Three simulated heads (each its own crystal, boot time and trigger latency) on one external
trigger line driven by the first head at ``--fps``, streamed through ``stereocam.CameraGroup``,
once per transport: in-process (``sim://``), and served as separate processes over TCP (and pty)
on a machine-wide trigger line. Printed per transport: the spread of the mapped capture times
within each matched set (p50/p99/max, µs), and each head's clock-map error (frame host_time minus
the simulator's true exposure instant; mean and sigma, µs) beside the error the map itself
estimates. The truth comes from the simulator's API (``--truth-log`` files for served heads),
never from the wire.
"""
from __future__ import annotations

import contextlib
import os
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Callable, Iterator

import click
import numpy as np

import stereocam
from stereocam.clock import MapError
from stereocam.device_sim import SimulatedCamera, TriggerLine
from stereocam.device_sim.process import ServedSimulator
from stereocam.frame_sets import MatchedSet
from stereocam.protocol.params import Output
from stereocam.tools.options import CONTEXT, Finite, epilog

SEEDS = (4, 14, 25)  # units with large drifts of both signs (-46, +50, +45 ppm)
CONFIG = dict(width=160, height=120, outputs=int(Output.LEFT))  # timing, not imaging: keep the CPU for it


@dataclass
class Run:
    """What one transport's run captured: per set, each head's (sequence, host_time)."""

    sets: list[tuple[int, dict[str, tuple[int, float]]]] = field(default_factory=list)
    incomplete: list[tuple[int, tuple[str, ...]]] = field(default_factory=list)
    map_errors: dict[str, MapError] = field(default_factory=dict)


def capture(urls: list[str], seconds: float, fps: int, deadline: float = 0.5) -> Run:
    """The group makes the first head the trigger master (its ``trigger_output``) at ``fps``."""
    run = Run()
    with stereocam.CameraGroup(urls, config={**CONFIG, "fps": fps}, master=0, deadline=deadline,
                               timeout=5.0) as group:
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds:
            s: MatchedSet = group.get_set()
            if s.complete:
                run.sets.append((s.trigger_id, {n: (f.sequence, f.host_time) for n, f in s.frames.items()}))
            else:
                run.incomplete.append((s.trigger_id, s.missing))
        run.map_errors = group.clock_errors()
    return run


@contextlib.contextmanager
def inprocess_heads() -> Iterator[tuple[list[str], Callable[[str, int], float | None]]]:
    line = TriggerLine()
    sims = {f"SYNC{s}": SimulatedCamera(serial=f"SYNC{s}", seed=s, trigger_line=line) for s in SEEDS}
    try:
        yield [f"sim://?serial={n}" for n in sims], lambda name, seq: sims[name].truth.exposure_instant(seq)
    finally:
        for sim in sims.values():
            sim.close()


@contextlib.contextmanager
def served_heads(kind: str) -> Iterator[tuple[list[str], Callable[[str, int], float | None]]]:
    """Each head its own process, on one machine-wide trigger line; truth read from their logs."""
    spec = "pty" if kind == "pty" else "tcp:127.0.0.1:0"
    line = f"bench-sync-{os.getpid()}-{kind}"
    with tempfile.TemporaryDirectory(prefix="stereocam-sync-") as tmp, contextlib.ExitStack() as stack:
        logs = {f"SIM{s:05d}": Path(tmp) / f"{s}.truth" for s in SEEDS}
        servers = []
        for s in SEEDS:
            extra = ["--trigger-line", line, "--truth-log", str(logs[f"SIM{s:05d}"])]
            servers.append(stack.enter_context(ServedSimulator(spec, seed=s, extra=extra)))
        truth: dict[str, dict[int, float]] = {}

        def lookup(name: str, seq: int) -> float | None:
            if name not in truth:
                truth[name] = {int(a): float(b) for a, b in (ln.split() for ln in logs[name].read_text().splitlines())}
            return truth[name].get(seq)

        yield [srv.url for srv in servers], lookup


def report(kind: str, run: Run, truth: Callable[[str, int], float | None]) -> dict[str, float]:
    skew = np.array([max(t for _, t in h.values()) - min(t for _, t in h.values()) for _, h in run.sets]) * 1e6
    errs: dict[str, list[float]] = {}
    true_skew = []
    for _, heads in run.sets:
        known = {n: instant for n, (seq, _) in heads.items() if (instant := truth(n, seq)) is not None}
        for n, (_, t) in heads.items():
            if n in known:
                errs.setdefault(n, []).append((t - known[n]) * 1e6)
        if len(known) == len(heads):
            true_skew.append((max(known.values()) - min(known.values())) * 1e6)
    out: dict[str, float] = {"sets": len(run.sets), "incomplete": len(run.incomplete)}
    if len(skew):
        out.update(skew_p50_us=float(np.percentile(skew, 50)), skew_p99_us=float(np.percentile(skew, 99)),
                   skew_max_us=float(skew.max()))
    print(f"  {kind:<10} {len(run.sets):6d} {len(run.incomplete):5d} " + (
        f"{out['skew_p50_us']:7.1f} {out['skew_p99_us']:7.1f} {out['skew_max_us']:7.1f} "
        f"{np.median(true_skew) if true_skew else float('nan'):8.1f}" if len(skew) else "   (no complete sets)"))
    for n, e in sorted(errs.items()):
        a = np.array(e)
        est = run.map_errors[n].sigma * 1e6 if n in run.map_errors else float("nan")
        out[f"{n}_err_mean_us"], out[f"{n}_err_sigma_us"] = float(a.mean()), float(a.std())
        print(f"      {n:<12} clock map error vs truth: mean {a.mean():+7.1f} µs  sigma {a.std():6.1f} µs  "
              f"|max| {np.abs(a).max():7.1f} µs   map's own estimate: sigma {est:6.1f} µs")
    for tid, missing in run.incomplete[:5]:
        print(f"      trigger {tid}: no frame from {', '.join(missing)}")
    return out


@click.command("sync", context_settings=CONTEXT, epilog=epilog())
@click.option("--seconds", type=Finite(min=0, min_open=True), default=120.0, show_default=True,
              help="Capture time per transport.")
@click.option("--fps", type=click.IntRange(1, 120), default=30, show_default=True, help="The master head's frame rate.")
@click.option("--transports", default="inprocess,tcp,pty", show_default=True,
              help="Comma-separated: inprocess, tcp, pty.")
@click.option("--deadline", type=Finite(min=0, min_open=True), default=0.5, show_default=True,
              help="Seconds a set waits for its last head; a head is silent after no frame for this long "
                   "(at least 1 s). A busy host may need more.")
def command(**params: Any) -> dict[str, dict[str, float]]:
    """Several heads on one trigger line, how well their capture times agree."""
    args = SimpleNamespace(**params)
    kinds = [k.strip() for k in args.transports.split(",") if k.strip()]
    print(f"{len(SEEDS)} heads (seeds {SEEDS}) on one external trigger line at {args.fps:g} fps, "
          f"{CONFIG['width']}x{CONFIG['height']} left plane only, {args.seconds:g} s per transport.")
    print("skew = spread of the mapped capture times within a matched set; true = spread of the true exposure")
    print("instants (the heads' own trigger latencies). All figures in µs.")
    print(f"  {'transport':<10} {'sets':>6} {'incmp':>5} {'p50':>7} {'p99':>7} {'max':>7} {'true p50':>8}")
    out = {}
    for kind in kinds:
        heads = inprocess_heads() if kind == "inprocess" else served_heads(kind)
        with heads as (urls, truth):  # a frame's truth is logged before the frame is sent
            out[kind] = report(kind, capture(urls, args.seconds, args.fps, args.deadline), truth)
    return out
