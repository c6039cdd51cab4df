"""``stereocam demo``: a simulator, a few seconds of streaming, outputs in ./out/ and a summary."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from stereocam.device_sim import SimulatedCamera
from stereocam.device_sim.ground_truth import GROUND_TRUTH_KEEP
from stereocam.camera import Camera
from stereocam.device_sim.links.inprocess import InProcessTransport

from .capture import save_frame


def depth_errors(frame, truth) -> tuple[float, float, float]:
    """(valid %, median |depth error| %, bad-1px %) of one frame against the simulator's truth."""
    d = frame.disparity_px()
    z = frame.depth()
    valid = np.isfinite(z) & (truth.disparity_px > 0)
    rel = np.abs(z[valid] - truth.depth_m[valid]) / truth.depth_m[valid]
    bad1 = np.abs(d[valid] - truth.disparity_px[valid]) > 1.0
    return 100.0 * valid.mean(), 100.0 * float(np.median(rel)), 100.0 * float(bad1.mean())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="stereocam demo", description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out"))
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--fps", type=int, default=15)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)

    sim = SimulatedCamera(seed=args.seed)
    with Camera(InProcessTransport(sim, f"sim://?seed={args.seed}")) as cam:
        info = cam.info()
        print(f"camera: {info.model} serial {info.serial} firmware {info.firmware_version} "
              f"protocol {info.protocol_version[0]}.{info.protocol_version[1]}")
        cam.configure(width=640, height=480, fps=args.fps, num_disparities=64, block_size=15)
        cam.start()
        cam.get_frame(timeout=30.0)  # first frame pays the JIT warm-up
        recent: list = []
        frames = 0
        t0 = time.monotonic()
        while time.monotonic() - t0 < args.seconds:
            recent = (recent + [cam.get_frame(timeout=5.0)])[-GROUND_TRUTH_KEEP // 2:]
            frames += 1
        elapsed = time.monotonic() - t0
        cam.stop()
        host_stats = cam.stats
        dev = cam.status().counters
        stats = [depth_errors(f, sim.ground_truth(f.sequence)) for f in recent]  # truth after timing
        paths = save_frame(recent[-1], args.out, "demo")
    valid, med, bad1 = (float(np.mean([s[i] for s in stats])) for i in range(3))
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    link = host_stats["incomplete"] + host_stats["size_mismatch"] + host_stats["header_crc_errors"] + \
        host_stats["payload_crc_errors"]
    print(f"summary: frames={frames} fps={frames / elapsed:.1f} dropped={host_stats['frames_dropped']} "
          f"device_dropped={dev['frames_dropped']} host_queue_dropped={host_stats['queue_overflow']} "
          f"link_errors={link} valid_disparity={valid:.1f}% depth_error_median={med:.2f}% bad1px={bad1:.1f}%")
    return 0
