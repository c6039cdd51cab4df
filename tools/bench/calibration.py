"""Calibration accuracy benchmark: calibrate simulated units from rendered views, compare to truth.

For each seed: the unit's true calibration (truth.py), `--views` board poses (board.py) rendered
through it with sensor noise, then tools.calibration.solve.calibrate_pairs. Reported per seed:
  * relative error of fx, fy, cx, cy (worst of the two cameras) and of the baseline;
  * held-out epipolar RMS (the tool's own metric, includes corner detection noise);
  * true epipolar RMS (true_rectified_dy): random 3-D points (0.5–5 m, whole field of view) projected
    through the TRUE lenses of any model, then rectified with the ESTIMATED calibration as a unit does
    (stereo_rectify); RMS of y_left − y_right over the points both rectified images show.
Targets: every relative error ≤ 0.2 %, held-out epipolar RMS < 0.1 px. Exit status 1 if missed.
"""
from __future__ import annotations

import time
from types import SimpleNamespace
from typing import Any

import click
import numpy as np

from stereocam.device_sim.calibration.board import StereoBoardRenderer, board_poses
from stereocam.stereo.calibration_board import BoardSpec
from stereocam.device_sim.calibration.rays import lens_project
from stereocam.device_sim.calibration.truth import true_calibration
from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.rectification import stereo_rectify, viewing_rays
from stereocam.tools.calibration.solve import (
    SolveConfig,
    calibrate_pairs,
)
from stereocam.tools.options import CONTEXT, Finite, epilog

MAX_REL_ERROR = 0.002
MAX_EPIPOLAR_PX = 0.1


def true_rectified_dy(truth: StereoCalibration, stored: StereoCalibration, n: int = 4000) -> float:
    """RMS rectified row difference (px) of exact projections of random points 0.5-5 m away, seen
    through the true lenses, rectified as the unit does with its stored calibration (stereo_rectify),
    over the points that land in both rectified images."""
    rng = np.random.default_rng(0)
    w, h = truth.image_size
    pix = np.column_stack([rng.uniform(0, w - 1, n), rng.uniform(0, h - 1, n)])
    rays = viewing_rays(truth.K_left, truth.D_left, pix, 50, truth.lens_model)
    rays = rays[rays[:, 2] > 0.1]
    pts = rays / np.linalg.norm(rays, axis=1, keepdims=True) * rng.uniform(0.5, 5.0, (len(rays), 1))
    right = pts @ truth.R.T + truth.T.ravel()
    pts, right = pts[right[:, 2] > 0.1], right[right[:, 2] > 0.1]
    uv_l = lens_project(truth.K_left, truth.D_left, truth.lens_model, pts)
    uv_r = lens_project(truth.K_right, truth.D_right, truth.lens_model, right)
    inside = np.all((uv_r >= 0) & (uv_r <= [w - 1, h - 1]) & np.isfinite(uv_r), axis=1)
    geo = stereo_rectify(stored)
    rect = []
    for uv, K, D, R, P in ((uv_l[inside], stored.K_left, stored.D_left, geo.R1, geo.P1),
                           (uv_r[inside], stored.K_right, stored.D_right, geo.R2, geo.P2)):
        turned = viewing_rays(K, D, uv, 50, stored.lens_model) @ R.T
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = (P[:2, :2] @ (turned[:, :2] / turned[:, 2:]).T).T + P[:2, 2]
        rect.append(np.where(turned[:, 2:] > 0, xy, np.nan))
    seen = np.all((rect[0] >= 0) & (rect[0] <= [w - 1, h - 1]) & (rect[1] >= 0) & (rect[1] <= [w - 1, h - 1]), axis=1)
    dy = rect[0][seen, 1] - rect[1][seen, 1]  # points in both rectified images
    return float(np.sqrt(np.mean(dy ** 2))) if dy.size else float("nan")


def run_seed(seed: int, size: tuple[int, int], board: BoardSpec, views: int, noise: float,
             supersample: int) -> dict[str, float]:
    """Calibrate one simulated unit; returns its error figures."""
    truth = true_calibration(seed, size)
    renderer = StereoBoardRenderer(truth, board, supersample)
    rng = np.random.default_rng(seed)
    pairs = (renderer.render(p, rng, noise) for p in board_poses(seed, views, board, truth))
    res = calibrate_pairs(pairs, board, SolveConfig(max_views=views))
    est = res.calibration
    row = {}
    for name, (i, j) in (("fx", (0, 0)), ("fy", (1, 1)), ("cx", (0, 2)), ("cy", (1, 2))):
        row[name] = max(abs(est.K_left[i, j] / truth.K_left[i, j] - 1), abs(est.K_right[i, j] / truth.K_right[i, j] - 1))
    row["baseline"] = abs(est.baseline_m / truth.baseline_m - 1)
    row["rms_stereo"] = res.quality.rms_stereo
    row["epi_heldout"] = res.quality.epipolar_rms_px
    row["epi_true"] = true_rectified_dy(truth, est)
    row["views"] = res.quality.views_used
    return row


@click.command("calibration", context_settings=CONTEXT, epilog=epilog())
@click.option("--seeds", type=click.IntRange(min=1), default=5, show_default=True,
              help="Number of simulated units (seeds 0..N-1).")
@click.option("--views", type=click.IntRange(min=1), default=100, show_default=True, help="Board poses rendered per unit.")
@click.option("--width", type=click.IntRange(min=1), default=1280, show_default=True, help="Image width, px.")
@click.option("--height", type=click.IntRange(min=1), default=960, show_default=True, help="Image height, px.")
@click.option("--noise", type=Finite(min=0), default=1.0, show_default=True, help="Sensor noise sigma, DN.")
@click.option("--supersample", type=click.IntRange(min=1), default=1, show_default=True, help="Render supersampling.")
def command(**params: Any) -> int:
    """Calibration accuracy benchmark: calibrate simulated units from rendered views, compare to truth."""
    args = SimpleNamespace(**params)
    board = BoardSpec(9, 6, 0.025)
    print(f"board {board.cols}x{board.rows} x {board.square_m * 1000:.0f} mm, {args.width}x{args.height}, "
          f"{args.views} poses/unit, noise {args.noise} DN, supersample {args.supersample}")
    print(f"{'seed':>4} {'fx %':>7} {'fy %':>7} {'cx %':>7} {'cy %':>7} {'base %':>7} {'rms px':>7} "
          f"{'epi ho':>7} {'epi tr':>7} {'views':>5} {'time s':>6}")
    worst: dict[str, float] = {}
    for seed in range(args.seeds):
        t0 = time.perf_counter()
        row = run_seed(seed, (args.width, args.height), board, args.views, args.noise, args.supersample)
        for k, v in row.items():
            worst[k] = max(worst.get(k, 0.0), v)
        print(f"{seed:>4} " + " ".join(f"{100 * row[k]:>7.3f}" for k in ("fx", "fy", "cx", "cy", "baseline")) +
              f" {row['rms_stereo']:>7.3f} {row['epi_heldout']:>7.3f} {row['epi_true']:>7.3f} "
              f"{row['views']:>5} {time.perf_counter() - t0:>6.1f}")
    print("max  " + " ".join(f"{100 * worst[k]:>7.3f}" for k in ("fx", "fy", "cx", "cy", "baseline")) +
          f" {worst['rms_stereo']:>7.3f} {worst['epi_heldout']:>7.3f} {worst['epi_true']:>7.3f}")
    ok = all(worst[k] <= MAX_REL_ERROR for k in ("fx", "fy", "cx", "cy", "baseline")) and \
        worst["epi_heldout"] < MAX_EPIPOLAR_PX
    print(f"targets: relative errors <= {100 * MAX_REL_ERROR:.1f} %, held-out epipolar < {MAX_EPIPOLAR_PX} px: "
          + ("MET" if ok else "MISSED"))
    return 0 if ok else 1

