"""``stereocam bench matching --algorithm sgm``: every engine on every scene, one table per scene.

Scenes: Middlebury Motorcycle (scikit-image, 128 disparities) and each simulator scene class
(device_sim/rig/scene_classes.py, rendered by an ideal rectified rig with exact truth, the class's
disparity range scaled to the width: 64 at 640 px, driving 128), with its dense truth or (``sparse``)
a LiDAR-like subset of it (``lidar_subset``). Rows: our block matcher, our SGM with 8 and 4 paths, each post-processing preset
after our SGM (when ``stereocam.stereo.post`` is installed), cv2.StereoSGBM in every mode, cv2.StereoBM
and cv2's WLS filter (when cv2.ximgproc is installed). Columns: density (valid % of all pixels),
bad-2.0 over every pixel with truth (invalid counts as bad), bad-2.0 over the pixels the method
reported, end-point error (px, reported pixels), median ms and spread (max - min) of the timed runs,
and the median of the per-run ratio to cv2 SGBM_3WAY: the runs are interleaved, every method once per
round, so a ratio compares two methods on the same machine state.
"""
from __future__ import annotations

import contextlib
import dataclasses
import importlib
import os
import platform
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterator

import numpy as np

BAD_PX = 2.0
SGBM_MODES = {"SGBM": 0, "HH": 1, "SGBM_3WAY": 2, "HH4": 3}  # cv2.STEREO_SGBM_MODE_*
REFERENCE = "cv2 SGBM_3WAY"
CV2_INVALID = -16  # cv2's (minDisparity - 1) * 16 at minDisparity 0
MOTORCYCLE = "motorcycle"
MOTORCYCLE_DISPARITIES = 128
LIDAR_FRACTION = 0.07  # share of all pixels a sparse truth keeps
LIDAR_MIN_PX = 1.0  # no LiDAR return from farther than this disparity (the sky, far trees)
COLUMNS = ("method", "density %", "bad2 all %", "bad2 rep %", "EPE px", "ms", "spread", "x3WAY")

MatchFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class BenchScene:
    """A rectified pair and its truth (float32 px; NaN or inf where unknown)."""

    name: str
    left: np.ndarray
    right: np.ndarray
    truth: np.ndarray
    num_disparities: int


@dataclass(frozen=True)
class Method:
    """One row kind: builds its matcher for an image shape; ``invalid`` is its no-match code."""

    name: str
    make: Callable[[tuple[int, int]], MatchFn]
    invalid: int


@dataclass(frozen=True)
class Row:
    """One method's figures on one scene."""

    method: str
    density: float  # % of all pixels with a disparity
    bad_all: float  # % of pixels with truth that are invalid or more than BAD_PX off
    bad_reported: float  # % of reported pixels with truth that are more than BAD_PX off
    epe: float  # mean |disparity - truth| px over reported pixels with truth
    ms: float  # median of the timed runs
    spread_ms: float  # max - min of the timed runs
    ratio: float  # median of the per-round ratio to REFERENCE


def score(disp: np.ndarray, invalid: int, truth: np.ndarray) -> tuple[float, float, float, float]:
    """(density %, bad-2.0 all %, bad-2.0 reported %, EPE px) of an int16 disparity * 16; NaN for
    the three that need truth where there is none."""
    valid = disp != invalid
    known = np.isfinite(truth)
    if not known.any():
        return 100.0 * float(valid.mean()), float("nan"), float("nan"), float("nan")
    err = np.abs(disp.astype(np.float32) / 16.0 - np.where(known, truth, 0))
    reported = known & valid
    bad = err > BAD_PX
    n_known, n_rep = max(1, int(known.sum())), max(1, int(reported.sum()))
    return (100.0 * float(valid.mean()), 100.0 * float((known & (~valid | bad)).sum()) / n_known,
            100.0 * float((reported & bad).sum()) / n_rep, float(err[reported].sum()) / n_rep)


def class_scene(name: str, width: int, height: int, seed: int, sparse: bool = False) -> BenchScene:
    """A scene class rendered by the ideal rig (device_sim/rig/stereo_pair.py), at the class's
    disparity range for ``width`` (a multiple of 16); ``sparse``: scored on ``lidar_subset`` of the truth."""
    from stereocam.device_sim.rig.scene_classes import DISPARITIES_WIDTH
    from stereocam.device_sim.rig.stereo_pair import render_pair, scene_class

    pair = render_pair(name, width, height, seed=seed)
    nd = max(16, -(-scene_class(name).disparities * width // (16 * DISPARITIES_WIDTH)) * 16)
    truth = lidar_subset(pair.disparity, seed) if sparse else pair.disparity
    return BenchScene(f"{name} {width}x{height}{' sparse' if sparse else ''}", pair.left,
                      pair.right, truth, nd)


def lidar_subset(truth: np.ndarray, seed: int, fraction: float = LIDAR_FRACTION) -> np.ndarray:
    """``truth`` kept on a random ``fraction`` of all pixels (NaN elsewhere), as a LiDAR sees a
    street: a pixel's chance grows with the square of its row (mostly the lower image), and no
    return where the truth is below ``LIDAR_MIN_PX`` (sky, far background)."""
    h, w = truth.shape
    rows = ((np.arange(h) + 0.5) / h) ** 2
    seen = np.isfinite(truth) & (np.nan_to_num(truth) >= LIDAR_MIN_PX)
    weight = np.where(seen, rows[:, None], 0.0)
    chance = np.minimum(1.0, fraction * h * w * weight / max(float(weight.sum()), 1e-9))
    keep = np.random.default_rng([0x11DA2, seed]).random((h, w)) < chance
    return np.where(keep, truth, np.nan).astype(np.float32)


def motorcycle_scene() -> BenchScene:
    from .matching import motorcycle

    left, right, truth = motorcycle()
    return BenchScene(f"Motorcycle {left.shape[1]}x{left.shape[0]}", left, right, truth, MOTORCYCLE_DISPARITIES)


def methods(nd: int) -> tuple[list[Method], list[str]]:
    """Every row kind for ``nd`` disparities, and a note per kind skipped (a missing package)."""
    import cv2

    from stereocam.stereo import Matcher, MatchParams, SGMMatcher, SGMParams

    bm = MatchParams(num_disparities=nd, block_size=9)

    def ours_bm(shape: tuple[int, int]) -> MatchFn:
        return Matcher(shape, bm).match

    def ours_sgm(p: SGMParams) -> Callable[[tuple[int, int]], MatchFn]:
        return lambda shape: SGMMatcher(shape, p).match

    out = [Method("ours bm 9x9", ours_bm, bm.invalid_value)]
    sgm: dict[int, SGMParams] = {paths: SGMParams(num_disparities=nd, paths=paths) for paths in (5, 8, 4)}
    out += [Method(f"ours sgm {k} paths", ours_sgm(p), p.invalid_value) for k, p in sgm.items()]
    notes = []
    try:
        post = importlib.import_module("stereocam.stereo.post")
    except ImportError as exc:
        notes.append(f"post-processing presets skipped: stereocam.stereo.post is not importable ({exc})")
    else:
        from stereocam.protocol.params import defaults
        from stereocam.stereo import engines

        for preset, settings in post.POST_PRESETS.items():
            if preset == "off":
                continue
            cfg = {**defaults(), "num_disparities": nd, **settings}  # the preset as a device applies it
            engine_params = engines.params_from_config(cfg)

            def make_post(shape: tuple[int, int], cfg: dict[str, int] = cfg, ep: Any = engine_params) -> MatchFn:
                matcher = engines.matcher_for(cfg, shape)
                chain = post.post_params_from_config(cfg)
                return lambda left, right: post.postprocess(matcher.match(left, right), left, chain, right, ep)
            out.append(Method(f"ours {engines.selected(cfg).name} + {preset}", make_post,
                              engine_params.invalid_value))

    create_sgbm = getattr(cv2, "StereoSGBM_create", None) or cv2.StereoSGBM.create  # OpenCV 4.x or 5.x
    create_bm = getattr(cv2, "StereoBM_create", None) or cv2.StereoBM.create

    def sgbm(mode: int) -> Any:
        return create_sgbm(0, nd, 5, P1=200, P2=800, disp12MaxDiff=1, uniquenessRatio=10,
                           speckleWindowSize=100, speckleRange=2, mode=mode)

    def cv2_sgbm(mode: int) -> Callable[[tuple[int, int]], MatchFn]:
        return lambda shape: sgbm(mode).compute

    out += [Method(f"cv2 {name}", cv2_sgbm(code), CV2_INVALID) for name, code in SGBM_MODES.items()]

    def stereo_bm(shape: tuple[int, int]) -> MatchFn:
        m = create_bm(nd, 9)
        m.setSpeckleWindowSize(100)
        m.setSpeckleRange(32)
        return m.compute
    out.append(Method("cv2 StereoBM 9x9", stereo_bm, CV2_INVALID))
    ximgproc = getattr(cv2, "ximgproc", None)
    if ximgproc is not None:
        def wls(shape: tuple[int, int]) -> MatchFn:
            left_m = sgbm(SGBM_MODES["SGBM_3WAY"])
            right_m = ximgproc.createRightMatcher(left_m)
            f = ximgproc.createDisparityWLSFilter(left_m)
            return lambda left, right: f.filter(left_m.compute(left, right), left, None,
                                                right_m.compute(right, left)).astype(np.int16)
        out.append(Method("cv2 SGBM_3WAY + WLS", wls, CV2_INVALID))
    else:
        notes.append(f"cv2 WLS skipped: cv2.ximgproc is not in this OpenCV ({cv2.__version__}; "
                     "it ships with opencv-contrib-python)")
    return out, notes


def measure(scene: BenchScene, kinds: list[Method], repeat: int) -> list[Row]:
    """Score every method on ``scene`` and time ``repeat`` interleaved rounds of all of them."""
    fns = [k.make(scene.left.shape) for k in kinds]
    scores = [score(fn(scene.left, scene.right), k.invalid, scene.truth) for fn, k in zip(fns, kinds)]
    times: list[list[float]] = [[] for _ in kinds]
    for _ in range(repeat):
        for fn, ts in zip(fns, times):
            t0 = time.perf_counter()
            fn(scene.left, scene.right)
            ts.append((time.perf_counter() - t0) * 1e3)
    ref = next((ts for k, ts in zip(kinds, times) if k.name == REFERENCE), None)
    rows = []
    for k, sc, ts in zip(kinds, scores, times):
        ratio = statistics.median(t / r for t, r in zip(ts, ref)) if ref else float("nan")
        rows.append(Row(k.name, *sc, statistics.median(ts), max(ts) - min(ts), ratio))
    return rows


def misaligned(scene: BenchScene, dy: float) -> BenchScene:
    """``scene`` with its right image moved down by ``dy`` px (bilinear, edges replicated; up when
    negative): the vertical residual a real unit's rectification leaves, which the simulator's
    scenes (rectified exactly) and Motorcycle do not have. The truth, the left image's, is kept."""
    if dy == 0:
        return scene
    import cv2

    h, w = scene.right.shape
    right = cv2.warpAffine(scene.right, np.array([[1, 0, 0], [0, 1, dy]], np.float32), (w, h), flags=cv2.INTER_LINEAR,
                           borderMode=cv2.BORDER_REPLICATE)
    return dataclasses.replace(scene, name=f"{scene.name} right {dy:+g} px", right=right)


def format_table(scene: BenchScene, rows: list[Row]) -> str:
    """The scene's table: a title line, the column names, a rule and one line per method."""
    h, w = scene.left.shape
    head = f"{COLUMNS[0]:<24}" + "".join(f"{c:>11}" for c in COLUMNS[1:])
    lines = [f"== {scene.name}, {scene.num_disparities} disparities, truth on "
             f"{100 * np.isfinite(scene.truth).mean():.0f} % of {w}x{h} ==", head, "-" * len(head)]

    def cell(v: float, digits: int) -> str:
        return f"{'-' if np.isnan(v) else f'{v:.{digits}f}':>11}"

    for r in rows:
        lines.append(f"{r.method:<24}{cell(r.density, 1)}{cell(r.bad_all, 1)}{cell(r.bad_reported, 1)}"
                     f"{cell(r.epe, 2)}{cell(r.ms, 1)}{cell(r.spread_ms, 1)}{cell(r.ratio, 2)}")
    return "\n".join(lines)


def cpu_name() -> str:
    with contextlib.suppress(OSError):
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine()


def vector_target() -> str:
    """The CPU numba compiles the kernels for and the SGM kernels' vector width: their speed
    against cv2 depends on it (stereo/simd.py)."""
    from llvmlite import binding
    from numba import config

    from stereocam.stereo.simd import LANES
    target = getattr(config, "CPU_NAME", None) or binding.get_host_cpu_name()
    return f"numba target {target}, SGM vectors of {LANES} lanes"


def header(threads: int, busy: bool, repeat: int) -> str:
    import cv2
    import numba

    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    return (f"threads {threads} (cv2 and numba); {'beside a busy process' if busy else 'no busy process'}; "
            f"repeat {repeat}; load average {load} on {os.cpu_count()} cpus ({cpu_name()}; {vector_target()})\n"
            f"python {platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}, "
            f"cv2 {cv2.__version__}")


SPIN = "print('spinning', flush=True)\nwhile True: pass"


@contextlib.contextmanager
def busy_process(on: bool) -> Iterator[None]:
    """A competing process spinning on one core while the block runs (``on``), stopped after;
    the block starts once it spins (a Python start-up takes tens of ms, a small frame a few)."""
    if not on:
        yield
        return
    proc = subprocess.Popen([sys.executable, "-c", SPIN], stdout=subprocess.PIPE)
    try:
        assert proc.stdout is not None
        proc.stdout.readline()  # "spinning", or nothing if it died
        yield
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def report(scenes: list[Callable[[], BenchScene]], threads: int, repeat: int, busy: bool) -> list[list[Row]]:
    """Print the header and one table per scene (loaded lazily, in order); return the rows."""
    import cv2
    import numba

    from stereocam.stereo.engines import engine_named

    cv2.setNumThreads(threads)
    numba_config: Any = numba.config
    numba.set_num_threads(min(threads, numba_config.NUMBA_NUM_THREADS))
    t0 = time.perf_counter()
    for name in ("bm", "sgm"):
        engine_named(name).warm_up()
    out = []
    with busy_process(busy):
        print(header(threads, busy, repeat))
        print(f"JIT warm-up {time.perf_counter() - t0:.1f} s; bad-2.0 all: invalid counts as bad; "
              f"x3WAY: median per-round time ratio to {REFERENCE} (interleaved)")
        notes_shown = set()
        for load in scenes:
            scene = load()
            kinds, notes = methods(scene.num_disparities)
            for note in notes:
                if note not in notes_shown:
                    print(f"({note})")
                    notes_shown.add(note)
            rows = measure(scene, kinds, repeat)
            print(format_table(scene, rows), flush=True)
            out.append(rows)
        print(f"load average at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return out
