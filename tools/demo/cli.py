"""stereocam demo: a simulator, a few seconds of streaming, outputs in ./out/ and a summary."""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import click
import numpy as np
from tqdm import tqdm

from stereocam.camera import Camera
from stereocam.device_sim import SimulatedCamera
from stereocam.device_sim.ground_truth import GROUND_TRUTH_KEEP
from stereocam.device_sim.links.inprocess import SEED_MAX, InProcessTransport

from stereocam.tools.camera.capture import save_frame
from stereocam.tools.camera.session import output_dir
from stereocam.tools.options import CONTEXT, SETTING, Finite, epilog
from stereocam.tools.progress import progress_wanted

from . import group as demo_group

KEEP_UP = 0.9  # below this share of the asked frame rate the summary says the machine fell short
MAX_SECONDS = 24 * 3600.0  # the longest demo


def depth_errors(frame, truth) -> tuple[float, float, float]:
    """(valid %, median |depth error| %, bad-1px %) of one frame against the simulator's truth."""
    d = frame.disparity_px()
    z = frame.depth()
    valid = np.isfinite(z) & (truth.disparity_px > 0)
    rel = np.abs(z[valid] - truth.depth_m[valid]) / truth.depth_m[valid]
    bad1 = np.abs(d[valid] - truth.disparity_px[valid]) > 1.0
    return 100.0 * valid.mean(), 100.0 * float(np.median(rel)), 100.0 * float(bad1.mean())


@dataclass(frozen=True)
class Drops:
    """The frames of the timed run that never reached the user, split into parts that add up to the
    total: the user's sequence numbers say how many are missing; the host knows the ones its queue
    discarded; the device's counter says how many it dropped (at most what is left); ``other`` is the
    rest (lost on the link, or dropped by the device after its counter was read)."""

    total: int
    device: int
    host_queue: int
    other: int

    @classmethod
    def of(cls, first_seq: int, last_seq: int, frames: int, device: int, host_queue: int) -> "Drops":
        total = max(last_seq - first_seq + 1 - frames, 0)
        host_queue = min(host_queue, total)
        device = min(device, total - host_queue)
        return cls(total, device, host_queue, total - host_queue - device)


def keep_up_note(fps: float, asked: int, dropped: int) -> str:
    """One plain sentence: did this machine keep up with the frame rate asked for?"""
    if fps >= KEEP_UP * asked:
        return f"kept up: {fps:.1f} of the {asked} fps asked for"
    return (f"this machine could not keep up: {fps:.1f} of the {asked} fps asked for ({dropped} frames dropped); "
            f"the simulator renders and matches every frame on this CPU - try a lower --fps, or fewer other "
            f"programs running")


@click.command("demo", epilog=epilog(), context_settings=CONTEXT)
@click.option("--out", type=click.Path(path_type=Path), default=Path("out"), show_default=True,
              help="Directory for the outputs (images, disparity with a depth colour bar, point cloud).")
@click.option("--seconds", type=Finite(0, MAX_SECONDS, min_open=True), default=4.0, show_default=True,
              help="How long to stream.")
@click.option("--fps", type=click.IntRange(1, 120), default=15, show_default=True, help="Frame rate to ask for.")
@click.option("--seed", type=click.IntRange(0, SEED_MAX), default=1, show_default=True,
              help="Which simulated unit (with --heads N: the first; the others take the next N-1 seeds).")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as one JSON object instead of lines.")
@click.option("--heads", type=click.IntRange(1, 8), default=1, show_default=True,
              help="Several heads on one trigger line, streamed as matched sets (CameraGroup).")
@click.option("--set", "settings", type=SETTING, multiple=True,
              help="Configure every camera after the demo's own settings (repeatable), e.g. --set gain=40.")
def command(out: Path, seconds: float, fps: int, seed: int, as_json: bool, heads: int,
            settings: tuple[tuple[str, int], ...]) -> int:
    """Stream from an in-process simulated camera at 640x480, save the last frame's outputs and print a
    summary: frame rate (and whether this machine kept up), drops, link errors, depth accuracy against
    the simulator's ground truth."""
    if seed + heads - 1 > SEED_MAX:
        raise click.BadParameter(f"{heads} heads take the seeds {seed}..{seed + heads - 1}: at most {SEED_MAX}",
                                 param_hint="'--seed'")
    output_dir(out)
    if heads > 1:
        return demo_group.run(heads, seconds, fps, seed, out, dict(settings))
    sim = SimulatedCamera(seed=seed)
    with Camera(InProcessTransport(sim, f"sim://?seed={seed}")) as cam:
        info = cam.info()
        if not as_json:
            click.echo(f"camera: {info.model} serial {info.serial} firmware {info.firmware_version} "
                       f"protocol {info.protocol_version[0]}.{info.protocol_version[1]}")
        cam.configure(**{"width": 640, "height": 480, "fps": fps, "num_disparities": 64, "block_size": 15,
                         **dict(settings)})
        cam.start()
        cam.get_frame(timeout=30.0)  # first frame pays the JIT warm-up
        host0, dev0 = cam.stats, cam.status().counters
        recent: list = []
        first_seq = None  # the timed run's drops are counted from its first frame on (not the warm-up's)
        frames = 0
        t0 = time.monotonic()
        with tqdm(total=round(seconds * fps), unit="frame", desc="demo", disable=not progress_wanted()) as bar:
            while not frames or time.monotonic() - t0 < seconds:  # at least one frame, however short
                recent = (recent + [cam.get_frame(timeout=5.0)])[-GROUND_TRUTH_KEEP // 2:]
                first_seq = recent[-1].sequence if first_seq is None else first_seq
                frames += 1
                bar.update()
        elapsed = time.monotonic() - t0
        host_stats, dev = cam.stats, cam.status().counters
        cam.stop()
        assert first_seq is not None  # the loop takes at least one frame
        drops = Drops.of(first_seq, recent[-1].sequence, frames, dev["frames_dropped"] - dev0["frames_dropped"],
                         host_stats["queue_overflow"] - host0["queue_overflow"])
        stats = [depth_errors(f, sim.ground_truth(f.sequence)) for f in recent]  # truth after timing
        paths = save_frame(recent[-1], out, "demo")
    valid, med, bad1 = (float(np.mean([s[i] for s in stats])) for i in range(3))
    link = sum(host_stats[k] - host0[k] for k in ("incomplete", "size_mismatch", "header_crc_errors",
                                                  "payload_crc_errors"))
    summary = {"frames": frames, "fps": round(frames / elapsed, 1), "fps_asked": fps,
               "dropped": drops.total, "device_dropped": drops.device, "host_queue_dropped": drops.host_queue,
               "other_dropped": drops.other, "link_errors": link,
               "valid_disparity_pct": round(valid, 1), "depth_error_median_pct": round(med, 2),
               "bad1px_pct": round(bad1, 1), "files": {k: str(p) for k, p in paths.items()},
               "note": keep_up_note(frames / elapsed, fps, drops.total)}
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return 0
    click.echo("wrote " + ", ".join(str(p) for p in paths.values()))
    click.echo(f"summary: frames={frames} fps={frames / elapsed:.1f} dropped={drops.total} "
               f"device_dropped={drops.device} host_queue_dropped={drops.host_queue} other_dropped={drops.other} "
               f"link_errors={link} valid_disparity={valid:.1f}% depth_error_median={med:.2f}% bad1px={bad1:.1f}%")
    click.echo(summary["note"])
    return 0
