"""``stereocam bench post``: the on-board post-processing chain (stereocam.stereo.post).

Timing: SGM (64 disparities) plus each preset's chain at 640x480 on the simulator's lab scene, median
ms per stage over --repeat runs (and their spread), with the fps the matcher plus chain allow.
--quality: density (valid pixels), bad-2.0 over every pixel with known truth (invalid counts as bad)
and over the valid ones alone
of SGM raw and with each preset, against cv2.StereoSGBM in every mode (block 5, P1 200, P2 800,
disp12MaxDiff 1, uniqueness 10, speckle 100 / 2), on the synthetic scene, the simulator's lab and wall
scenes and Middlebury Motorcycle (when scikit-image has it).
"""
from __future__ import annotations

import functools
import os
import statistics
import time
from typing import Any

import click
import numpy as np

from stereocam.tools.options import CONTEXT, epilog

from .matching import bad_rate, motorcycle, synthetic_scene
from .sgm import SGBM_MODES, sim_scene

NUM_DISPARITIES = 64


def _scenes(quick: bool) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
    out = [("synthetic 640x480", *synthetic_scene())]
    for scene in ("lab", "wall"):
        out.append((f"sim {scene} 640x480", *sim_scene(640, 480, scene)))
    if not quick:
        try:
            out.append(("Motorcycle 741x500", *motorcycle()))
        except Exception as exc:  # scikit-image or its data missing
            print(f"(Motorcycle skipped: {exc})")
    return out


def _sgm(nd: int, cfg: dict[str, int]):
    from stereocam.stereo.engines import engine_for
    from stereocam.protocol.params import defaults
    full = {**defaults(), "algorithm": 1, "num_disparities": nd, **cfg}
    return engine_for(full["algorithm"]).params_from_config(full)


def _methods(nd: int):
    """(label, run(left, right) -> disparity, invalid code)."""
    import cv2

    from stereocam.stereo import match
    from stereocam.stereo.post import POST_PRESETS, PostChain, post_params_from_config
    from stereocam.stereo.post.lr_check import right_view_disparity

    out = []
    for name, cfg in {"SGM raw": {}, **{f"SGM {k}": dict(v) for k, v in POST_PRESETS.items() if k != "off"}}.items():
        ep = _sgm(nd, cfg)
        post = post_params_from_config(cfg)

        def run(left, right, ep=ep, post=post):
            disp = match(left, right, ep)
            if not post.active:
                return disp
            return PostChain(post, ep.min_disparity).run(
                disp, lambda: right_view_disparity(lambda a, b: match(a, b, ep), left, right))
        out.append((name, run, ep.invalid_value))
    for mode, code in SGBM_MODES.items():
        sgbm = cv2.StereoSGBM_create(0, nd, 5, P1=200, P2=800, disp12MaxDiff=1, uniquenessRatio=10,  # type: ignore[attr-defined]
                                     speckleWindowSize=100, speckleRange=2, mode=code)
        out.append((f"cv2 {mode}", sgbm.compute, -16))
    return out


def quality(quick: bool) -> None:
    methods = _methods(NUM_DISPARITIES)
    print(f"{'scene':<20} {'method':<18} {'density':>8} {'bad2.0':>7} {'of valid':>8}")
    for scene, left, right, gt in _scenes(quick):
        for name, run, invalid in methods:
            disp = run(left, right)
            density = float(np.count_nonzero(disp != invalid)) / disp.size
            valid = (disp != invalid) & np.isfinite(gt)
            of_valid = float(np.count_nonzero(valid & (np.abs(disp / 16.0 - gt) > 2.0))) / max(1, int(valid.sum()))
            print(f"{scene:<20} {name:<18} {100 * density:>7.2f}% {100 * bad_rate(disp, gt, invalid):>6.2f}% "
                  f"{100 * of_valid:>7.2f}%")


def timing(repeat: int) -> None:
    from stereocam.stereo import SGMMatcher
    from stereocam.stereo.post import POST_PRESETS, STAGES, PostChain, post_params_from_config
    from stereocam.stereo.post.lr_check import right_view_disparity

    left, right, _ = sim_scene(640, 480, "lab")
    for name, cfg in POST_PRESETS.items():
        ep = _sgm(NUM_DISPARITIES, dict(cfg))
        m, mirror = SGMMatcher(left.shape, ep), SGMMatcher(left.shape, ep)
        chain = PostChain(post_params_from_config(cfg), ep.min_disparity)
        per: dict[str, list[float]] = {k: [] for k in ("match", *STAGES, "total")}
        for i in range(repeat + 1):
            t0 = time.perf_counter()
            disp = m.match(left, right)
            t1 = time.perf_counter()
            chain.run(disp, functools.partial(right_view_disparity, mirror.match, left, right))
            t2 = time.perf_counter()
            if i == 0:
                continue  # the first run pays any compilation
            per["match"].append((t1 - t0) * 1e3)
            for k in STAGES:
                per[k].append(chain.stage_ms[k])
            per["total"].append((t2 - t0) * 1e3)
        med = {k: statistics.median(v) for k, v in per.items()}
        print(f"{name:<14} " + ", ".join(f"{k} {med[k]:.1f}" for k in per)
              + f" ms (total spread {min(per['total']):.1f}..{max(per['total']):.1f}, chain fastest "
              f"{min(t - m for t, m in zip(per['total'], per['match'])):.1f}); {1e3 / med['total']:.1f} fps")


@click.command("post", context_settings=CONTEXT, epilog=epilog())
@click.option("--threads", type=click.IntRange(min=1), default=2, show_default=True, help="numba threads.")
@click.option("--repeat", type=click.IntRange(min=1), default=10, show_default=True, help="Timed runs per preset.")
@click.option("--quality", "with_quality", is_flag=True, help="Also density and bad-2.0 against cv2 SGBM.")
@click.option("--quick", is_flag=True, help="Quality without Motorcycle.")
def command(**params: Any) -> int:
    """Time the post-processing chain per stage at 640x480 (and its quality with --quality)."""
    import numba

    numba.set_num_threads(min(params["threads"], numba.config.NUMBA_NUM_THREADS))  # type: ignore[attr-defined]
    print(f"numba {numba.__version__}, threads {numba.get_num_threads()}; repeat={params['repeat']}; "
          f"SGM {NUM_DISPARITIES} disparities; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cpus")
    timing(params["repeat"])
    if params["with_quality"]:
        quality(params["quick"])
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")
    return 0
