"""stereocam bench transport: end-to-end figures of a simulated camera per transport and algorithm.

640x480, 64 disparities, left + right + disparity, 60 fps asked, free run. Per transport: the fps
the whole chain sustains, the MB/s of plane data it carried, the exposures it dropped (sequence
gaps the host saw) and trigger-to-frame latency (the exposure instant, mapped to the host clock,
to the moment ``get_frame`` returned it) p50/p99. Where the device runs in this process (sim and
usb) also the device's stage profile (ms per frame, wall) and the process CPU per frame.

``--rates``: the pipeline's rate targets instead, over sim and TCP: VGA block matching at 60 fps
asked, VGA SGM (64 disparities) at 30 fps asked, and SGM with the high-density post-processing
chain at 30 fps (skipped with a note until ``stereocam.stereo.post`` is installed).
"""
from __future__ import annotations

import contextlib
import importlib.util
import os
import time
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any, Iterator

import click
import numpy as np
from tqdm import tqdm

from stereocam.stereo import engines
from stereocam.tools.options import CONTEXT, Finite, epilog
from stereocam.tools.progress import progress_wanted

if TYPE_CHECKING:
    from stereocam.device_sim import SimulatedCamera

KINDS = ("sim", "pty", "tcp", "usb-high", "usb-super")
CORES = 2
RATE_KINDS = ("sim", "tcp")
POST_CHAIN = "high_density"  # the SDK preset naming the post-processing chain (stereocam.stereo.post)


@dataclass(frozen=True)
class RateCase:
    """One pipeline rate target: an engine at a frame rate asked, optionally with a post chain."""

    algorithm: str
    fps: int
    preset: str | None = None

    @property
    def label(self) -> str:
        return f"VGA {self.algorithm.upper()} 64 disp" + (f" + {self.preset}" if self.preset else "")


RATE_CASES = (RateCase("bm", 60), RateCase("sgm", 30), RateCase("sgm", 30, POST_CHAIN))


@dataclass
class Run:
    kind: str
    fps: float
    mbps: float
    drops: int
    p50_ms: float
    p99_ms: float
    cpu_ms: float | None = None  # process CPU per delivered frame (device and host in this process)
    stages: dict[str, float] = field(default_factory=dict)  # device stage ms per frame (wall)


@contextlib.contextmanager
def _device(kind: str) -> Iterator[tuple[str, SimulatedCamera | None]]:
    """A simulator reachable over ``kind``: (URL, the in-process SimulatedCamera or None)."""
    from stereocam.device_sim import SimulatedCamera
    from stereocam.device_sim.process import ServedSimulator

    if kind in ("pty", "tcp"):
        with ServedSimulator("pty" if kind == "pty" else "tcp:127.0.0.1:0", seed=1) as server:
            yield server.url, None
        return
    serial = f"BENCH-{kind.upper()}"
    sim = SimulatedCamera(serial=serial, seed=1)
    try:
        if kind == "sim":
            yield f"sim://?serial={serial}", sim
        else:
            import stereocam.device_sim.usb as simusb

            handle = simusb.plug(sim, speed=kind.split("-")[1])
            try:
                yield f"usb://?serial={serial}", sim
            finally:
                handle.unplug()
    finally:
        sim.close()


def stream(kind: str, algorithm: str, seconds: float, fps: int = 60, preset: str | None = None) -> Run:
    """Stream for ``seconds`` over ``kind`` at ``fps`` asked (after the SDK ``preset``, if named) and measure."""
    import stereocam

    settings = dict(width=640, height=480, fps=fps, num_disparities=64, block_size=15,
                    algorithm=engines.engine_named(algorithm).algorithm)
    with _device(kind) as (url, sim), stereocam.open(url, timeout=3.0) as cam:
        if preset is not None:
            cam.load_preset(preset)
        cam.configure(**settings)
        cam.start()
        for _ in range(3):
            cam.get_frame(timeout=60.0)  # warm-up: JIT cache load, the first frame of the format
        dropped0 = cam.stats["frames_dropped"]
        if sim is not None:
            sim.pipeline.profile.reset()
        lat, nbytes, n = [], 0, 0
        cpu0, t0 = time.process_time(), time.monotonic()
        with tqdm(total=round(seconds * fps), unit="frame", desc=f"{kind} {algorithm}", leave=False,
                  disable=not progress_wanted()) as bar:
            while time.monotonic() - t0 < seconds:
                f = cam.get_frame(timeout=5.0)
                lat.append(time.monotonic() - f.host_time)
                nbytes += sum(a.nbytes for a in (f.left, f.right, f.disparity) if a is not None)
                n += 1
                bar.update()
        dt, cpu = time.monotonic() - t0, time.process_time() - cpu0
        drops = cam.stats["frames_dropped"] - dropped0
        cam.stop()
    p50, p99 = np.percentile(lat, [50, 99]) * 1e3
    run = Run(kind, n / dt, nbytes / dt / 1e6, drops, float(p50), float(p99))
    if sim is not None:
        run.cpu_ms = cpu / n * 1e3
        run.stages = sim.pipeline.profile.per_frame()
    return run


def report(runs: list[Run], algorithm: str) -> None:
    print(f"  {'transport':<10} {'fps':>6} {'MB/s':>7} {'drops':>6} {'p50 ms':>7} {'p99 ms':>7} {'CPU ms/frame':>13}")
    for r in runs:
        cpu = f"{r.cpu_ms:13.1f}" if r.cpu_ms is not None else f"{'(2 processes)':>13}"
        print(f"  {r.kind:<10} {r.fps:6.1f} {r.mbps:7.1f} {r.drops:6d} {r.p50_ms:7.1f} {r.p99_ms:7.1f} {cpu}")
    profiled = [r for r in runs if r.stages]
    if profiled:
        names = list(profiled[0].stages)
        print(f"device stage profile ({algorithm}), ms per delivered frame, wall time on this machine "
              "(render on the capture thread; rectify, match, send on the delivery thread, overlapping it):")
        print(f"  {'transport':<10} " + " ".join(f"{s:>8}" for s in names))
        for r in profiled:
            print(f"  {r.kind:<10} " + " ".join(f"{r.stages[s]:8.2f}" for s in names))
        best = min(r.cpu_ms for r in profiled if r.cpu_ms is not None)  # in-process runs: all of them
        print(f"ESTIMATE, not a measurement: on {CORES} idle cores, at {best:.1f} ms of CPU per frame (device and "
              f"host together, least of the in-process runs), the chain could carry about "
              f"{1e3 * CORES / best:.0f} fps if its stages overlapped perfectly.")


def rates(seconds: float) -> dict[str, float]:
    """Print the achieved fps of every RATE_CASES row over every RATE_KINDS transport."""
    print(f"pipeline rate at 640x480, 64 disparities, left + right + disparity, {seconds:g} s each; "
          f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cpus (sim: device in this process, "
          "tcp: in a second one):")
    print(f"  {'case':<30} {'transport':<9} {'asked':>5} {'fps':>6} {'drops':>6} {'p50 ms':>7} {'p99 ms':>7}")
    out: dict[str, float] = {}
    for case in RATE_CASES:
        if case.preset is not None and importlib.util.find_spec("stereocam.stereo.post") is None:
            print(f"  {case.label:<30} (skipped: stereocam.stereo.post, the post-processing chain, is not installed)")
            continue
        for kind in RATE_KINDS:
            r = stream(kind, case.algorithm, seconds, case.fps, case.preset)
            print(f"  {case.label:<30} {kind:<9} {case.fps:>5} {r.fps:6.1f} {r.drops:6d} {r.p50_ms:7.1f} "
                  f"{r.p99_ms:7.1f}", flush=True)
            out[f"{kind}_{case.label}_fps"] = r.fps
            if r.stages and r.cpu_ms is not None:  # the device in this process: where a frame's time goes
                print(f"  {'':<30} {'':<9} device stages, ms per frame (wall): "
                      + ", ".join(f"{k} {v:.1f}" for k, v in r.stages.items())
                      + f" (render: the simulated sensor); CPU {r.cpu_ms:.1f} ms per frame, device and host",
                      flush=True)
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")
    return out


@click.command("transport", context_settings=CONTEXT, epilog=epilog())
@click.option("--algorithm", type=click.Choice(engines.names()), multiple=True,
              help="Matching engine on the device (repeatable).  [default: bm]")
@click.option("--transport", "kinds", type=click.Choice(KINDS), multiple=True,
              help="Transport to measure (repeatable).  [default: all]")
@click.option("--seconds", type=Finite(min=0, min_open=True), default=5.0, show_default=True,
              help="Capture time per transport.")
@click.option("--rates", is_flag=True, help="The pipeline rate targets over sim and TCP: VGA BM at 60 fps, "
                                            "VGA SGM (64 disparities) at 30 fps, SGM + post-processing chain.")
def command(**params: Any) -> dict[str, float]:
    """End-to-end figures of a simulated camera per transport and algorithm."""
    args = SimpleNamespace(**params)
    if args.rates:
        return rates(args.seconds)
    out: dict[str, float] = {}
    for algorithm in args.algorithm or ["bm"]:
        print(f"end-to-end at 640x480, 64 disparities, all three planes, 60 fps asked, {algorithm}, "
              f"{args.seconds:.0f} s each (sim and usb run the device in this process, pty and tcp in a second one):")
        runs = [stream(kind, algorithm, args.seconds) for kind in args.kinds or KINDS]
        report(runs, algorithm)
        out.update({f"{r.kind}_{algorithm}_fps": r.fps for r in runs})
    return out
