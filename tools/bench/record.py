"""``stereocam bench record``: the recorder's ceiling, and a live recording at the camera's full rate.

Ceiling: distinct 1280x960 captures of a simulator (left, right, disparity) pushed into a Recorder
as fast as it takes them (waiting for room, so nothing is dropped), to a real file; figures are
captures/s and MB/s of camera data (planes as the camera sends them: 1 + 1 + 2 bytes per pixel).
The issue's yardstick is 1280x960, three planes at 30 fps ≈ 110 MB/s: the ceiling must reach 2×.
Live: a simulator at 640x480 recorded for a few seconds through the SDK; recorder drops must be 0.
Seek: random frames of a 10 000-frame recording, each read through the file's indexes alone.
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import click
import numpy as np
import zstandard

import stereocam
from stereocam.recording import Recorder, UnitDescription, convert, describe
from stereocam.recording.reader import Recording
from stereocam.tools.options import CONTEXT, Finite, epilog

YARDSTICK_MBPS = 1280 * 960 * 3 * 30 / 1e6  # the "1280x960, three planes, 30 fps"


def _frames(n: int, width: int, height: int) -> tuple[list[stereocam.Frame], UnitDescription]:
    with stereocam.open("sim://?seed=3", timeout=3.0) as cam:
        cam.configure(width=width, height=height, fps=30)
        cam.start()
        frames = [cam.get_frame(timeout=60.0) for _ in range(n)]
        cam.stop()
        return frames, describe(cam)


def _zstd_alone(frame: stereocam.Frame, level: int, seconds: float = 1.0) -> float:
    """Captures/s that zstd alone compresses on one thread: the recorder's work per capture, minus I/O."""
    pieces = [p for p in (frame.left, frame.right, convert.disparity_to_float(frame)) if p is not None]
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        z = zstandard.ZstdCompressor(level=level).compressobj()
        for p in pieces:
            z.compress(p.data)
        z.flush()
        n += 1
    return n / (time.perf_counter() - t0)


def bench_ceiling(seconds: float, level: int, threads: int, out_dir: Path, width: int = 1280, height: int = 960
                  ) -> dict[str, float]:
    frames, unit = _frames(6, width, height)
    alone = _zstd_alone(frames[0], level)
    path = out_dir / f"ceiling{width}.mcap"
    rec = Recorder(path, unit, level=level, threads=threads)
    t0 = time.perf_counter()
    n = 0
    while time.perf_counter() - t0 < seconds:
        f = frames[n % len(frames)]
        f.host_time += 1 / 30  # a new capture instant each time
        rec.put_wait(f)
        n += 1
    stats = rec.close()
    dt = time.perf_counter() - t0
    mbps = stats.camera_bytes / dt / 1e6
    three = n * width * height * 3 / dt / 1e6
    print(f"recorder ceiling ({width}x{height}, 3 planes, zstd level {level}, {threads} compression threads): "
          f"{n / dt:.1f} captures/s = {mbps:.0f} MB/s of camera data ({three:.0f} MB/s counted as 3 bytes/px); "
          f"file {stats.file_bytes / dt / 1e6:.0f} MB/s, {stats.file_bytes / stats.camera_bytes:.2f} of the input")
    print(f"  for scale, in the same run: zstd alone on one thread compresses {alone:.1f} captures/s "
          f"(this machine is shared: figures move with its load)")
    print(f"  yardstick 1280x960 x 3 planes x 30 fps = {YARDSTICK_MBPS:.0f} MB/s: ceiling is "
          f"{three / YARDSTICK_MBPS:.2f}x it (target >= 2x), recorder drops {stats.recorder_dropped}")
    return {"captures_per_s": n / dt, "camera_MBps": mbps, "ratio_to_yardstick": three / YARDSTICK_MBPS}


def bench_live(seconds: float, out_dir: Path) -> dict[str, float]:
    with stereocam.open("sim://?seed=3", timeout=3.0) as cam:
        cam.configure(width=640, height=480, fps=30)
        cam.start()
        cam.get_frame(timeout=60.0)  # warm-up
        stats = cam.record(out_dir / "live.mcap", seconds=seconds)
    c = stats.counters
    fps = stats.frames / seconds
    print(f"live 640x480 x 3 planes for {seconds:.0f} s through the SDK: {stats.frames} captures ({fps:.1f}/s, the "
          f"simulator's full rate here), drops: recorder {stats.recorder_dropped}, sequence gaps {c.link_lost} "
          f"(device skipped {c.device_dropped}), incomplete {c.link_incomplete}, host {c.host_queue_overflow}")
    return {"live_fps": fps, "live_recorder_dropped": stats.recorder_dropped}


def synthetic_recording(path: Path, frames: int, width: int = 64, height: int = 48) -> None:
    """A recording of ``frames`` small synthetic captures (distinct noise planes, 30 fps timing)."""
    rng = np.random.default_rng(0)
    planes = [(rng.integers(0, 256, (height, width), np.uint8), rng.integers(0, 256, (height, width), np.uint8),
               rng.integers(-16, 64 * 16, (height, width)).astype(np.int16)) for _ in range(16)]
    info = {"model": "STOC-SYNTH", "serial": "SYNTH0001", "firmware_version": "0", "protocol_version": "1.1"}
    unit = UnitDescription(info, {"width": width, "height": height, "fps": 30}, None)
    with Recorder(path, unit) as rec:
        for i in range(frames):
            left, right, disp = planes[i % len(planes)]
            rec.put_wait(stereocam.Frame(i + 1, 0, 1_000_000 + i * 33_333, 100.0 + i / 30, left, right, disp, 4000, 0,
                                         width, height, True, stereocam.DisparityFormat(16, 0, 64, -16),
                                         stereocam.StereoGeometry(60.0, width / 2, height / 2, 0.1)))


def bench_seek(frames: int, out_dir: Path, probes: int = 20) -> dict[str, float]:
    path = out_dir / "long.mcap"
    t0 = time.perf_counter()
    synthetic_recording(path, frames)
    built = time.perf_counter() - t0
    rng = np.random.default_rng(1)
    t0 = time.perf_counter()
    with Recording(path) as rec:
        opened = time.perf_counter() - t0
        times = []
        for i in rng.integers(0, frames, probes):
            t = time.perf_counter()
            assert rec.capture(int(i)).info.sequence == i + 1
            times.append(time.perf_counter() - t)
        chunks = len(rec.summary.chunk_indexes)
    print(f"seek by frame index in a {frames}-frame recording ({chunks} chunks, 64x48, written in {built:.1f} s): "
          f"open {opened * 1e3:.1f} ms, then median {np.median(times) * 1e3:.1f} ms, max {max(times) * 1e3:.1f} ms "
          f"per random frame ({probes} probes)")
    return {"seek_median_ms": float(np.median(times) * 1e3), "open_ms": opened * 1e3}


@click.command("record", context_settings=CONTEXT, epilog=epilog())
@click.option("--seconds", type=Finite(min=0, min_open=True), default=5.0, show_default=True,
              help="Time per measurement.")
@click.option("--level", type=int, default=1, show_default=True, help="zstd level of the chunks.")
@click.option("--threads", type=click.IntRange(min=1), default=2, show_default=True, help="Compression threads.")
@click.option("--seek-frames", type=click.IntRange(min=1), default=10_000, show_default=True,
              help="Length of the recording to seek in.")
@click.option("--dir", type=click.Path(file_okay=False), default=None,
              help="Where to write the files.  [default: a temporary folder]")
def command(**params: Any) -> int:
    """The recorder's ceiling, and a live recording at the camera's full rate."""
    args = SimpleNamespace(**params)
    with tempfile.TemporaryDirectory(prefix="stereocam-bench-", dir=args.dir) as tmp:
        bench_ceiling(args.seconds, args.level, args.threads, Path(tmp))
        r = bench_ceiling(args.seconds, args.level, args.threads, Path(tmp), 640, 480)
        print(f"  at 640x480 the recorder takes {r['captures_per_s']:.0f} captures/s: "
              f"{r['captures_per_s'] / 30:.1f}x the camera's 30 fps")
        bench_live(args.seconds, Path(tmp))
        bench_seek(args.seek_frames, Path(tmp))
    return 0
