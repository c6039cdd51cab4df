"""Benchmark the device matching core against cv2.StereoBM in one process.

    stereocam bench matching [--threads 2] [--repeat 15] [--quick] [--profile]
                             [--cold-jit] [--algorithm bm|sgm] [--scenes NAME ...] [--busy]
                             [--vertical-error PX]

``--algorithm sgm`` prints matching_report.py's tables instead (every engine on Motorcycle and every
simulator scene class; with ``--profile``, sgm.py's stage profile and CPU table).

Prints per case: median ms of each (runs interleaved), ratio core/cv2, G disparity
evaluations/s (W*H*D/time), bad-2.0 against ground truth (Middlebury Motorcycle from
scikit-image, and the synthetic scene's exact shifts; invalid counts as bad, unknown ground
truth skipped), bit-identical, peak extra memory per call (tracemalloc) and the matcher's
scratch size, plus the JIT warm-up. The load average is printed because timings on a shared
machine are only comparable within one run.
"""
from __future__ import annotations

import functools

import statistics
import sys
import time
import tracemalloc
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Callable

import click
import numpy as np

from stereocam.device_sim.rig.scene_classes import CLASSES
from stereocam.protocol.params import BY_NAME
from stereocam.stereo import engines
from stereocam.tools.bench.stereobm_oracle import opencv_stereobm
from stereocam.tools.options import CONTEXT, INPUT_FILE, Finite, epilog, multiple_of_16

from .matching_report import MOTORCYCLE, BenchScene, class_scene, misaligned, motorcycle_scene, report
from .pair_files import pair_scene


def synthetic_scene(h: int = 480, w: int = 640, seed: int = 0):
    """Smoothed random texture: background at 20 px, a slanted plane and a box nearer."""
    rng = np.random.default_rng(seed)
    pad = 160
    base = rng.integers(0, 256, (h, w + 2 * pad)).astype(np.float32)
    k = np.array([1, 2, 1], np.float32) / 4
    base = np.apply_along_axis(lambda v: np.convolve(v, k, "same"), 1, base)
    base = np.apply_along_axis(lambda v: np.convolve(v, k, "same"), 0, base)
    base = base.astype(np.uint8)
    right = base[:, pad:pad + w].copy()
    gt = np.full((h, w), 20.0, np.float32)
    gt[:, :] += np.linspace(0, 12, w)[None, :] * (np.arange(h)[:, None] > h // 2)
    gt[h // 5:h // 2, w // 4:w // 2] = 45.0
    xs = np.arange(w)[None, :] + pad - np.rint(gt).astype(int)
    left = np.take_along_axis(base, xs, axis=1)
    return left.astype(np.uint8), right, gt


def motorcycle():
    import cv2
    from skimage import data
    left, right, gt = data.stereo_motorcycle()
    return (cv2.cvtColor(left, cv2.COLOR_RGB2GRAY), cv2.cvtColor(right, cv2.COLOR_RGB2GRAY),
            gt.astype(np.float32))


def bad_rate(disp: np.ndarray, gt: np.ndarray, invalid: int, thr: float = 2.0) -> float:
    """Middlebury bad-thr over known pixels (finite gt); invalid output counts as bad."""
    known = np.isfinite(gt)
    d = disp.astype(np.float32) / 16.0
    bad = (disp == invalid) | (np.abs(d - gt) > thr)
    return float(np.count_nonzero(bad & known)) / max(1, int(np.count_nonzero(known)))


def _median_ms(fn, repeat: int) -> float:
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(ts)


def _cache_present() -> bool:
    d = Path(engines.__file__).resolve().parent / "__pycache__"
    return d.is_dir() and any(d.glob("*.nbi"))


def cold_jit_seconds() -> float:
    """Seconds a fresh process needs to import the core and compile every kernel."""
    import os
    import subprocess
    import tempfile
    code = ("import time; t0 = time.perf_counter(); from stereocam.stereo.engines import warm_up; "
            "warm_up(); print(time.perf_counter() - t0)")
    root = Path(__file__).resolve().parent.parent
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, NUMBA_CACHE_DIR=tmp)
        res = subprocess.run([sys.executable, "-c", code], cwd=root, env=env, check=True,
                             capture_output=True, text=True)
    return float(res.stdout.strip().splitlines()[-1])


def profile_stages(m, left, right, repeat: int) -> dict[str, float]:
    """Median ms per pipeline stage of Matcher m.

    'cost volume' runs the SAD stage with a texture threshold no pixel passes, so it times the
    running sums alone; 'wta+subpixel+lr' is the SAD stage minus that."""
    from dataclasses import replace

    from stereocam.stereo import Matcher
    from stereocam.stereo.postfilter import filter_speckles
    from stereocam.stereo.prefilter import prefilter_pair
    p = m.params
    disp = m.match(left, right)
    out = {"prefilter": _median_ms(lambda: prefilter_pair(
        left, right, m.pl, m.pr, p.pre_filter_type, p.pre_filter_size, p.pre_filter_cap,
        m.pf_vsum), repeat)}
    stage = _median_ms(lambda: m.run_sad(disp), repeat)
    mc = Matcher(left.shape, replace(p, texture_threshold=BY_NAME["texture_threshold"].hi, disp12_max_diff=-1))
    mc.match(left, right)
    out["cost volume"] = _median_ms(lambda: mc.run_sad(disp), repeat)
    out["wta+subpixel+lr"] = stage - out["cost volume"]
    if p.use_speckle:
        out["speckle"] = _median_ms(lambda: filter_speckles(
            disp.copy(), p.invalid_value, p.speckle_window_size, p.speckle_range, m.labels,
            m.stack, m.size, m.parent, m.rtype), repeat)
    out["total"] = _median_ms(lambda: m.match(left, right), repeat)
    return out


SCENE_CHOICES = [MOTORCYCLE, *CLASSES]


def _given(scene: BenchScene) -> BenchScene:
    return scene


def _moved(load: Callable[[], BenchScene], dy: float) -> BenchScene:
    return misaligned(load(), dy)


def sgm_report(args: SimpleNamespace) -> int:
    """The per-scene tables of matching_report.py for the scenes asked."""
    names = list(args.scene_names) or ([] if args.pairs else SCENE_CHOICES)
    w, h = (320, 240) if args.quick else args.size
    scenes: list[Callable[[], BenchScene]] = []
    truths = list(args.truths) or [None] * len(args.pairs)
    for (left, right), truth in zip(args.pairs, truths):  # read now: a bad file fails before any timing
        scene = pair_scene(left, right, truth, args.num_disparities, args.truth_scale)
        scenes.append(functools.partial(_given, scene))
    for name in names:
        if name == MOTORCYCLE:
            if args.quick:
                continue
            try:
                motorcycle()
            except Exception as exc:  # skimage missing or data unavailable
                print(f"(Motorcycle skipped: {exc})")
                continue
            scenes.append(motorcycle_scene)
        else:
            scenes.append(functools.partial(class_scene, name, w, h, args.seed, args.sparse_truth))
    if args.vertical_error:
        scenes = [functools.partial(_moved, load, args.vertical_error) for load in scenes]
    report(scenes, args.threads, args.repeat, args.busy)
    return 0


@click.command("matching", context_settings=CONTEXT, epilog=epilog())
@click.option("--threads", type=click.IntRange(min=1), default=2, show_default=True, help="Threads for both.")
@click.option("--repeat", type=click.IntRange(min=1), default=None,
              help="Timed runs per case.  [default: 15 for bm, 5 for sgm]")
@click.option("--quick", is_flag=True, help="Only 640x480, D=64, block 9 (sgm: the scene classes at 320x240, no Motorcycle).")
@click.option("--profile", is_flag=True, help="Per-stage timings of the core.")
@click.option("--cold-jit", is_flag=True, help="Also time a from-scratch compile (subprocess, empty numba cache).")
@click.option("--algorithm", type=click.Choice(engines.names()), default="bm", show_default=True,
              help="bm: the block matcher vs cv2.StereoBM; sgm: our SGM vs every cv2.StereoSGBM mode and StereoBM.")
@click.option("--scenes", "scene_names", type=click.Choice(SCENE_CHOICES), multiple=True,
              help="sgm: scenes to measure (repeatable).  [default: motorcycle and every scene class]")
@click.option("--size", type=(click.IntRange(min=64), click.IntRange(min=48)), default=(640, 480), show_default=True,
              metavar="W H", help="sgm: the scene classes' image size.")
@click.option("--seed", type=int, default=0, show_default=True, help="sgm: the scene classes' placement and texture.")
@click.option("--sparse-truth", is_flag=True,
              help="sgm: score the scene classes on a LiDAR-like 7 % of their truth, mostly in the lower image "
                   "and none from the sky (KITTI-style; for driving).")
@click.option("--busy", is_flag=True, help="sgm: run beside a competing busy process (one core spinning).")
@click.option("--pair", "pairs", type=(INPUT_FILE, INPUT_FILE), multiple=True, metavar="LEFT RIGHT",
              help="sgm: a rectified pair of image files (colour turned grey) to measure instead of the built-in "
                   "scenes (repeatable; --scenes adds those).")
@click.option("--truth", "truths", type=INPUT_FILE, multiple=True, metavar="FILE",
              help="sgm: the left image's disparity truth of each --pair, in order: PFM (inf unknown), a 16-bit "
                   "PNG (KITTI: value / 256, 0 unknown) or .npy (non-finite unknown).  [default: none: density and "
                   "time only]")
@click.option("--num-disparities", type=click.IntRange(min=16), default=None, callback=multiple_of_16, metavar="D",
              help="sgm: disparities searched on the --pair scenes (a multiple of 16).  [default: past the truth's "
                   "largest, else 128]")
@click.option("--truth-scale", type=Finite(min=0, min_open=True), default=None, metavar="S",
              help="sgm: disparity = truth value / S (an 8-bit PNG needs it).  [default: 256 for a 16-bit PNG, "
                   "else 1]")
@click.option("--vertical-error", type=Finite(-8, 8), default=0.0, show_default=True, metavar="PX",
              help="sgm: move every right image down by PX pixels (bilinear; negative: up) before matching, "
                   "as the residual of a real unit's rectification would.")
def command(**params: Any) -> int:
    """Benchmark the device matching core against cv2.StereoBM in one process; --algorithm sgm: every
    engine on Motorcycle and every simulator scene class, or on pairs of files, one table per scene."""
    args = SimpleNamespace(**params)
    if args.pairs or args.truths or args.num_disparities or args.truth_scale:
        if args.algorithm != "sgm" or args.profile:
            raise click.UsageError("--pair, --truth, --num-disparities and --truth-scale go with --algorithm sgm "
                                   "(without --profile)")
        if not args.pairs:
            raise click.UsageError("--truth, --num-disparities and --truth-scale need --pair")
        if args.truths and len(args.truths) != len(args.pairs):
            raise click.UsageError(f"{len(args.truths)} --truth for {len(args.pairs)} --pair: give one per pair "
                                   "(in the same order) or none")
    if args.algorithm == "sgm":
        if args.repeat is None:
            args.repeat = 5
        if args.profile:
            from .sgm import main as sgm_main
            return sgm_main(args)
        return sgm_report(args)
    if args.repeat is None:
        args.repeat = 15

    import cv2
    import numba

    cached = _cache_present()
    t0 = time.perf_counter()
    from stereocam.stereo import Matcher, MatchParams
    t_import = time.perf_counter() - t0
    cv2.setNumThreads(args.threads)
    numba.set_num_threads(min(args.threads, numba.config.NUMBA_NUM_THREADS))  # type: ignore[attr-defined]

    sl, sr, sgt = synthetic_scene()
    scenes = [("synthetic 640x480", sl, sr, sgt)]
    if not args.quick:
        try:
            scenes.append(("Motorcycle 741x500", *motorcycle()))
        except Exception as exc:  # skimage missing or data unavailable
            print(f"(Motorcycle skipped: {exc})")
    cases = [(64, 9)] if args.quick else [(64, 9), (64, 15), (128, 9), (128, 15)]

    t_jit = engines.warm_up() + t_import  # compiles, or loads numba's disk cache of, every kernel

    import os
    print(f"threads={args.threads} (cv2 {cv2.__version__}, numba {numba.__version__}, "
          f"numba threads {numba.get_num_threads()}); repeat={args.repeat}; "
          f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cpus")
    print(f"JIT warm-up (import + first calls): {t_jit:.2f} s "
          f"({'loaded from numba disk cache' if cached else 'compiled from scratch'})")
    if args.cold_jit:
        print(f"JIT compile from scratch (subprocess, empty cache): {cold_jit_seconds():.2f} s")
    hdr = (f"{'scene':<19} {'D':>4} {'blk':>3} {'core ms':>8} {'cv2 ms':>8} {'ratio':>6} "
           f"{'core G/s':>8} {'cv2 G/s':>8} {'bad2.0':>7} {'bitexact':>8} {'peak MiB':>8} "
           f"{'scratch MiB':>11}")
    print(hdr)
    print("-" * len(hdr))
    for name, left, right, gt in scenes:
        h, w = left.shape
        for nd, bs in cases:
            p = MatchParams(num_disparities=nd, block_size=bs)
            m = Matcher(left.shape, p)
            bm = opencv_stereobm(p)
            ours = m.match(left, right)
            ref = bm.compute(left, right)
            same = bool(np.array_equal(ours, ref))
            t_core, t_cv = [], []
            for _ in range(args.repeat):  # interleave so both see the same machine state
                t_core.append(_median_ms(lambda: m.match(left, right), 1))
                t_cv.append(_median_ms(lambda: bm.compute(left, right), 1))
            mc, mcv = statistics.median(t_core), statistics.median(t_cv)
            tracemalloc.start()
            m.match(left, right)
            peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
            scratch = m.scratch_bytes()
            bad = bad_rate(ours, gt, p.invalid_value)
            evals = w * h * nd
            print(f"{name:<19} {nd:>4} {bs:>3} {mc:>8.2f} {mcv:>8.2f} {mc / mcv:>6.2f} "
                  f"{evals / mc / 1e6:>8.2f} {evals / mcv / 1e6:>8.2f} "
                  f"{f'{100 * bad:.1f}%':>7} {'yes' if same else 'NO':>8} "
                  f"{peak / 2**20:>8.2f} {scratch / 2**20:>11.2f}")
            if args.profile:
                prof = profile_stages(m, left, right, args.repeat)
                print("    profile (ms): " + ", ".join(f"{k} {v:.2f}" for k, v in prof.items()))
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")
    return 0

