"""``stereocam bench matching --algorithm sgm``: our SGM against every cv2.StereoSGBM mode and
cv2.StereoBM, side by side in one run.

Scenes: Middlebury Motorcycle (scikit-image) and the simulator's ground-truth scenes (lab and
wall, rendered, rectified and fetched over sim:// with SimulatedCamera.ground_truth) at 640x480
and 1280x960. Per method: median ms of interleaved runs, the median and range of its time over
SGBM_3WAY's in the same round, G disparity evaluations/s (W*H*D/t), bad-2.0 and bad-1.0 over
pixels with known truth (invalid output counts as bad), and peak memory (growth of the process's
peak resident set over constructing the matcher and its first call). ``--busy`` times beside one
spinning process. First a subpixel table: pixel-locking bias on slanted planes with exact truth;
``--profile`` adds stage timings, CPU time per scene and, without ``--quick``, a table over image
sizes and disparity ranges.
"""
from __future__ import annotations

import os
import statistics
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .matching import bad_rate, motorcycle
from .matching_report import busy_process, vector_target

SGBM_MODES = {"SGBM": 0, "HH": 1, "SGBM_3WAY": 2, "HH4": 3}  # cv2.STEREO_SGBM_MODE_*


@dataclass
class Method:
    name: str
    make: Callable[[tuple[int, int]], Callable[[np.ndarray, np.ndarray], np.ndarray]]
    invalid: int


def methods(nd: int, variants: dict[str, dict]) -> list[Method]:
    """Our SGM per variant, cv2.StereoSGBM in each mode (block 5, P1 = 8*25, P2 = 32*25,
    uniqueness 10, speckle 100 / 2, as in REFERENCE.md section 5) and cv2.StereoBM 9x9."""
    import cv2

    from stereocam.stereo import SGMMatcher, SGMParams

    out = []
    for label, kw in variants.items():
        p = SGMParams(num_disparities=nd, **kw)
        out.append(Method(label, lambda shape, p=p: SGMMatcher(shape, p).match, p.invalid_value))
    for mode, code in SGBM_MODES.items():
        def make(shape, code=code):
            return cv2.StereoSGBM_create(0, nd, 5, 8 * 25, 32 * 25, 0, 0, 10, 100, 2,
                                         code).compute
        out.append(Method(f"cv2 {mode}", make, -16))

    def make_bm(shape):
        bm = cv2.StereoBM_create(nd, 9)
        bm.setSpeckleWindowSize(100)
        bm.setSpeckleRange(32)
        return bm.compute
    out.append(Method("cv2 StereoBM 9x9", make_bm, -16))
    return out


def sim_scene(width: int, height: int, scene: str, seed: int = 3):
    """(left, right, truth disparity with NaN where unknown) of one simulator capture."""
    from stereocam.camera import Camera
    from stereocam.device_sim import SimulatedCamera
    from stereocam.device_sim.links.inprocess import InProcessTransport
    from stereocam.protocol.params import Output

    sim = SimulatedCamera(seed=seed, scene=scene)  # a simulator setting, never a device parameter
    try:
        with Camera(InProcessTransport(sim, f"sim://?seed={seed}")) as cam:
            cam.configure(width=width, height=height, outputs=int(Output.LEFT | Output.RIGHT))
            cam.start()
            frame = cam.get_frame(timeout=120.0)
            cam.stop()
            truth = sim.ground_truth(frame.sequence)
    finally:
        sim.close()
    gt = np.where(truth.disparity_px > 0, truth.disparity_px, np.nan).astype(np.float32)
    return frame.left, frame.right, gt


def _status_kib(field: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    raise KeyError(field)


def peak_growth_mib(fn: Callable[[], object]) -> float:
    """MiB by which the process's peak resident set exceeds its current one while fn runs
    (Linux: /proc/self/clear_refs resets the peak); NaN where that is unavailable."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        base = _status_kib("VmRSS")
        fn()
        return (_status_kib("VmHWM") - base) / 1024
    except OSError:
        return float("nan")


def run(scenes, nd: int, repeat: int, variants: dict[str, dict]) -> None:
    hdr = (f"{'scene':<22} {'method':<18} {'ms':>8} {'x3WAY':>6} {'spread':>11} {'GDE/s':>6} "
           f"{'bad2.0':>7} {'bad1.0':>7} {'peak MiB':>8}")
    print(hdr)
    print("-" * len(hdr))
    for name, left, right, gt in scenes:
        h, w = left.shape
        rows = []
        fns = []
        for meth in methods(nd, variants):
            holder = {}

            def first_call(meth=meth, holder=holder):
                holder["fn"] = meth.make(left.shape)
                holder["fn"](left, right)
            mem = peak_growth_mib(first_call)
            fn = holder["fn"]
            disp = fn(left, right)
            fns.append(fn)
            rows.append([meth.name, [], bad_rate(disp, gt, meth.invalid, 2.0),
                         bad_rate(disp, gt, meth.invalid, 1.0), mem])
        for _ in range(repeat):  # interleaved, so every method sees the same machine state
            for row, fn in zip(rows, fns):
                t0 = time.perf_counter()
                fn(left, right)
                row[1].append((time.perf_counter() - t0) * 1e3)
        ms = {row[0]: statistics.median(row[1]) for row in rows}
        three_way = next(row[1] for row in rows if row[0] == "cv2 SGBM_3WAY")
        for label, times, b2, b1, mem in rows:
            ratios = [t / t3 for t, t3 in zip(times, three_way)]  # per interleaved round
            print(f"{name:<22} {label:<18} {ms[label]:>8.1f} {statistics.median(ratios):>6.2f} "
                  f"{min(ratios):>5.2f}-{max(ratios):<5.2f} {w * h * nd / ms[label] / 1e6:>6.2f} "
                  f"{100 * b2:>6.1f}% {100 * b1:>6.1f}% {mem:>8.1f}")
        print()


def profile(left: np.ndarray, right: np.ndarray, nd: int, repeat: int, variants) -> None:
    """Per-stage median ms of our SGM (stages as the matcher runs them; CPU ms on one thread,
    process time, where marked: robust to a busy machine)."""
    from stereocam.stereo import SGMMatcher, SGMParams
    from stereocam.stereo.postfilter import filter_speckles

    from .sgm_profile import cpu_ms, stage_ms

    for label, kw in variants.items():
        p = SGMParams(num_disparities=nd, **kw)
        m = SGMMatcher(left.shape, p)
        disp = m.match(left, right)

        def med(fn):
            ts = []
            for _ in range(repeat):
                t0 = time.perf_counter()
                fn()
                ts.append((time.perf_counter() - t0) * 1e3)
            return statistics.median(ts)
        out = {"census+aggregate+select (+speckle with 5 paths, 2 threads)":
               med(lambda: m.run_sgm(left, right, disp))}
        if p.use_speckle:
            out["speckle (1 thread)"] = med(lambda: filter_speckles(
                disp.copy(), p.invalid_value, p.speckle_window_size, p.speckle_range,
                m.labels, m.stack, m.size, m.parent, m.rtype))
        stages = stage_ms(m, left, right, repeat)
        both = "" if p.paths == 5 else ", both groups"
        out.update({f"{k} (CPU, 1 thread{both})": v for k, v in stages.items()})
        out["total (2 threads)"] = med(lambda: m.match(left, right))
        out["total (CPU, 1 thread)"] = cpu_ms(lambda: m.match(left, right), repeat)
        print(f"profile {label} {left.shape[1]}x{left.shape[0]}x{nd} (ms): "
              + ", ".join(f"{k} {v:.1f}" for k, v in out.items()))


def cpu_table(scenes, nd: int, repeat: int, variants: dict[str, dict]) -> None:
    """CPU ms per frame on one thread (process time, so other load on the machine does not
    count), ours per variant vs cv2 SGBM_3WAY, per scene."""
    import cv2

    from stereocam.stereo import SGMMatcher, SGMParams

    from .sgm_profile import cpu_ms

    three_way = cv2.StereoSGBM_create(0, nd, 5, 8 * 25, 32 * 25, 0, 0, 10, 100, 2,
                                      SGBM_MODES["SGBM_3WAY"])
    print("CPU ms per frame on 1 thread (ours / cv2 SGBM_3WAY):")
    for name, left, right, _ in scenes:
        t3 = cpu_ms(lambda: three_way.compute(left, right), repeat)
        cells = []
        for label, kw in variants.items():
            m = SGMMatcher(left.shape, SGMParams(num_disparities=nd, **kw))
            t = cpu_ms(lambda: m.match(left, right), repeat)
            cells.append(f"{label} {t:.1f} ({t / t3:.2f}x)")
        print(f"  {name:<22} 3WAY {t3:.1f}; " + "; ".join(cells))
    print()


def size_table(left: np.ndarray, right: np.ndarray, repeat: int, variants: dict[str, dict],
               threads: int, busy: bool) -> None:
    """Ours per variant over cv2 SGBM_3WAY on one pair resized to 320x240 .. 1280x960 with 64,
    128 and 256 disparities: the median and range of CPU-time ratios of interleaved rounds on
    one thread, then (threads > 1) the median and range
    of wall-time ratios of interleaved runs on ``threads`` threads, beside a busy process when
    ``busy``; under each size the 5-path variant's CPU ms per stage (sgm_profile.stage_ms)."""
    import cv2
    import numba

    from stereocam.stereo import SGMMatcher, SGMParams

    from .sgm_profile import cpu_ratios, stage_ms

    print(f"per size and disparities, ours / cv2 SGBM_3WAY: CPU on 1 thread (median, range of "
          f"interleaved rounds); wall on {threads} "
          f"threads{' beside a busy process' if busy else ''} (median, range):")
    for w, h in ((320, 240), (640, 480), (1280, 960)):
        pair = [cv2.resize(im, (w, h), interpolation=cv2.INTER_AREA) for im in (left, right)]
        for nd in (64, 128, 256):
            if nd >= w // 2:
                continue
            three_way = cv2.StereoSGBM_create(0, nd, 5, 8 * 25, 32 * 25, 0, 0, 10, 100, 2,
                                              SGBM_MODES["SGBM_3WAY"]).compute
            ours = {label: SGMMatcher((h, w), SGMParams(num_disparities=nd, **kw)).match
                    for label, kw in variants.items()}
            t3, ratios = cpu_ratios(lambda: three_way(*pair),
                                    [lambda fn=fn: fn(*pair) for fn in ours.values()], repeat)
            cells = [f"{label} {statistics.median(r):.2f}x ({min(r):.2f}-{max(r):.2f})"
                     for label, r in zip(ours, ratios)]
            if threads > 1:
                numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
                cv2.setNumThreads(threads)
                fns = [three_way, *ours.values()]
                times: list[list[float]] = [[] for _ in fns]
                with busy_process(busy):
                    for _ in range(repeat):
                        for ts, fn in zip(times, fns):
                            t0 = time.perf_counter()
                            fn(*pair)
                            ts.append(time.perf_counter() - t0)
                for label, ts in zip(ours, times[1:]):
                    r = [t / t3w for t, t3w in zip(ts, times[0])]
                    cells.append(f"{label} {statistics.median(r):.2f}x "
                                 f"({min(r):.2f}-{max(r):.2f})")
            print(f"  {w}x{h} {nd} disp: 3WAY {t3:.1f} CPU ms; " + "; ".join(cells), flush=True)
            for label, kw in variants.items():
                m = SGMMatcher((h, w), SGMParams(num_disparities=nd, **kw))
                if m.params.paths == 5:  # where its time goes (CPU ms on 1 thread)
                    print(f"    {label} stages: " + ", ".join(
                        f"{k} {v:.2f}" for k, v in stage_ms(m, *pair, repeat).items()), flush=True)
    print()


def subpixel_table(variants: dict[str, dict]) -> None:
    """Mean error per bin of the truth's offset from the nearest whole pixel (pixel locking:
    + in the low bins, - in the high ones) and RMS error, on slanted textured planes with exact
    truth (tools/bench/sgm_scenes.py), ours vs cv2 SGBM_3WAY (parabola fit)."""
    import cv2

    from stereocam.stereo import SGMMatcher, SGMParams

    from .sgm_scenes import fraction_bias, slanted_plane

    nd = 48
    pairs = [slanted_plane(96, 320, d0 + 0.37 * seed, slope, seed)
             for slope, d0 in ((0.05, 10.3), (0.1, 11.1), (-0.09, 36.4)) for seed in range(2)]
    three_way = cv2.StereoSGBM_create(0, nd, 5, 8 * 25, 32 * 25, 0, 0, 10, 100, 2,
                                      SGBM_MODES["SGBM_3WAY"])
    meths = [(label, lambda l, r, kw=kw: SGMMatcher(l.shape, SGMParams(num_disparities=nd, **kw))
              .match(l, r), SGMParams(num_disparities=nd, **kw).invalid_value)
             for label, kw in variants.items()]
    meths.append(("cv2 SGBM_3WAY", three_way.compute, -16))
    print("subpixel on slanted planes 320x96, 48 disp (mean error px per truth-fraction bin "
          "-0.5..0.5; RMS):")
    for label, fn, invalid in meths:
        disp = np.concatenate([fn(l, r)[8:-8, nd + 4:-8] for l, r, _ in pairs])
        gt = np.concatenate([g[8:-8, nd + 4:-8] for _, _, g in pairs])
        bias, rms = fraction_bias(disp, gt, invalid)
        print(f"  {label:<18} " + " ".join(f"{b:+.3f}" for b in bias) + f"; RMS {rms:.3f} px")
    print()


def main(args) -> int:
    import cv2
    import numba

    cv2.setNumThreads(args.threads)
    numba.set_num_threads(min(args.threads, numba.config.NUMBA_NUM_THREADS))
    from stereocam.stereo.engines import engine_named
    t0 = time.perf_counter()
    engine_named("sgm").warm_up()
    print(f"threads={args.threads} (cv2 {cv2.__version__}, numba {numba.__version__}); "
          f"repeat={args.repeat}; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cpus"
          f" ({vector_target()});"
          f" SGM JIT warm-up {time.perf_counter() - t0:.2f} s")
    variants = {"ours SGM 8 paths": {"paths": 8}, "ours SGM 4 paths": {"paths": 4},
                "ours SGM 5 paths": {"paths": 5}}
    subpixel_table(variants)
    scenes = []
    try:
        scenes.append(("Motorcycle 741x500", *motorcycle()))
    except Exception as exc:  # skimage missing or data unavailable
        print(f"(Motorcycle skipped: {exc})")
    sizes = [(640, 480)] if args.quick else [(640, 480), (1280, 960)]
    for w, h in sizes:
        for scene in ("lab", "wall"):
            scenes.append((f"sim {scene} {w}x{h}", *sim_scene(w, h, scene)))
    nd = 128
    if args.profile:
        profile(*scenes[0][1:3], nd, args.repeat, variants)
        cpu_table(scenes, nd, args.repeat, variants)
    busy = getattr(args, "busy", False)
    if args.profile and not args.quick and scenes[0][0].startswith("Motorcycle"):
        size_table(*scenes[0][1:3], args.repeat, variants, args.threads, busy)
    print(f"timed beside one busy process: {'yes' if busy else 'no'}")
    with busy_process(busy):
        run(scenes, nd, args.repeat, variants)
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")
    return 0
