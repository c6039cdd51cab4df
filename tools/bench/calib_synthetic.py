"""The calibration tool on synthetic board views through every lens model, against the truth.

Each case is a stereo head (device_sim/calibration/lens_views.py: a lens model and the field of view
across the image width) and a board printed flat; `--pairs` poses of it are rendered through both
lenses with noise (every pixel traced back through the lens, so a 190-degree fisheye is exact), and
the images go through the tool as `stereocam calibrate --images` takes them (calibrate_pairs, lens
model `auto`, every pair used). Reported per case: the model chosen and the held-out error of each
model tried (or why it failed), the relative error of fx, fy, cx, cy (worst of the two cameras) and
of the baseline, the rotation error between the eyes, stereo RMS and held-out epipolar RMS.
Targets (issue 19): the case's own model chosen, or one the held-out pairs cannot tell from it (its
held-out error within the tool's tie margin of the case model's: the simpler one wins the tie), every
relative error <= 0.2 %, the gate passed.
Exit status 1 if a case misses them.
"""
from __future__ import annotations

import os
import re
import time
from collections.abc import Callable
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import click
import cv2
import numpy as np

from stereocam.device_sim.calibration import lens_views as views
from stereocam.tools.calibration.board_text import parse_board
from stereocam.tools.calibration.solve import CalibrationError, CalibrationResult, SolveConfig, calibrate_pairs
from stereocam.tools.options import CONTEXT, epilog

SIZE = (640, 400)
MAX_REL_ERROR = 0.002  # the 0.2 %
SQUARE_M = 0.03


@dataclass(frozen=True)
class Case:
    """A head (lens model, field of view across the width, degrees) and a board (its --board text
    and the printed texture), with the poses' options (lens_views.board_poses: distance range, reach, roll)."""

    model: str
    fov: float
    board: str
    texture: Callable[[], views.Texture]
    pairs: int = 14
    distance: tuple[float, float] = (0.2, 0.5)
    reach: float = 0.8
    roll: float = 0.5
    seed: int = 3


def _chess(cols: int, rows: int) -> Callable[[], views.Texture]:
    return lambda: views.chessboard(cols, rows, SQUARE_M)


def _charuco(legacy: bool, inverted: bool) -> Callable[[], views.Texture]:
    return lambda: views.charuco(8, 6, 0.04, 0.03, "DICT_4X4_250", legacy=legacy, inverted=inverted)


CHARUCO = "charuco:8x6:0.04:0.03:DICT_4X4_250"
APRILGRID = "aprilgrid:4x3:0.05:0.3"

CASES: dict[str, Case] = {
    "plumb_bob 60deg chessboard 7x7 any roll": Case("plumb_bob", 60, "7x7", _chess(7, 7), roll=np.pi),
    "plumb_bob 70deg chessboard 9x6": Case("plumb_bob", 70, "9x6", _chess(9, 6)),
    "plumb_bob 90deg chessboard 9x6": Case("plumb_bob", 90, "9x6", _chess(9, 6)),
    "plumb_bob 70deg charuco legacy": Case("plumb_bob", 70, CHARUCO, _charuco(True, False)),
    "plumb_bob 70deg charuco legacy inverted": Case("plumb_bob", 70, CHARUCO, _charuco(True, True)),
    "plumb_bob 70deg charuco current": Case("plumb_bob", 70, CHARUCO, _charuco(False, False)),
    "plumb_bob 70deg charuco current inverted": Case("plumb_bob", 70, CHARUCO, _charuco(False, True)),
    "plumb_bob 70deg aprilgrid 4x3": Case("plumb_bob", 70, APRILGRID, lambda: views.aprilgrid(4, 3, 0.05, 0.3),
                                          pairs=20, distance=(0.25, 0.55)),
    "rational 110deg chessboard 9x6": Case("rational_polynomial", 110, "9x6", _chess(9, 6), reach=0.9),
    "rational 130deg chessboard 9x6": Case("rational_polynomial", 130, "9x6", _chess(9, 6), reach=0.9),
    "rational 130deg chessboard 7x7 any roll": Case("rational_polynomial", 130, "7x7", _chess(7, 7),
                                                    reach=0.9, roll=np.pi),
    "rational 130deg charuco current": Case("rational_polynomial", 130, CHARUCO, _charuco(False, False),
                                            reach=0.9),
    "equidistant 150deg chessboard 9x6": Case("equidistant", 150, "9x6", _chess(9, 6)),
    "equidistant 150deg aprilgrid 4x3": Case("equidistant", 150, APRILGRID, lambda: views.aprilgrid(4, 3, 0.05, 0.3),
                                             pairs=20, distance=(0.15, 0.45)),
    "equidistant 170deg charuco legacy inverted": Case("equidistant", 170, CHARUCO, _charuco(True, True),
                                                       distance=(0.15, 0.4)),
    "equidistant 190deg chessboard 9x6": Case("equidistant", 190, "9x6", _chess(9, 6), distance=(0.15, 0.35),
                                              reach=0.9),
}
"""Every lens model at 60-190 degrees across the width, every board class (square and non-square
chessboards, ChArUco in both layouts and polarities, AprilGrid)."""

ERRORS = ("fx", "fy", "cx", "cy", "baseline")


def head_and_pairs(case: Case) -> tuple[views.Rig, list[tuple[np.ndarray, np.ndarray]]]:
    head = views.rig(case.model, case.fov, SIZE)
    return head, views.stereo_views(head, case.texture(), case.pairs, seed=case.seed, distance=case.distance,
                                    reach=case.reach, roll=case.roll)


def calibrate(case: Case, pairs: list[tuple[np.ndarray, np.ndarray]]) -> CalibrationResult:
    """The tool's solve on every pair, lens model `auto`."""
    board = parse_board(case.board, SQUARE_M if re.fullmatch(r"\d+x\d+", case.board) else None)
    return calibrate_pairs(iter(pairs), board, SolveConfig(), select=False)


def errors(result: CalibrationResult, head: views.Rig) -> dict[str, float]:
    """Relative errors (fractions; worst of the two cameras), and the rotation error in degrees."""
    c = result.calibration
    row = {}
    for name, (i, j) in (("fx", (0, 0)), ("fy", (1, 1)), ("cx", (0, 2)), ("cy", (1, 2))):
        row[name] = max(abs(c.K_left[i, j] / head.left.K[i, j] - 1), abs(c.K_right[i, j] / head.right.K[i, j] - 1))
    row["baseline"] = abs(c.baseline_m / float(np.linalg.norm(head.T)) - 1)
    row["rot_deg"] = float(np.degrees(np.linalg.norm(cv2.Rodrigues(c.R @ head.R.T)[0])))
    return row


def misses(case: Case, result: CalibrationResult, row: dict[str, float]) -> list[str]:
    """What the case misses of its targets (empty: met)."""
    out = []
    chosen = result.calibration.lens_model
    own = result.model_scores.get(case.model)
    if chosen != case.model and (own is None or result.model_scores[chosen] > own * (1 + SolveConfig().model_tie)):
        out.append(f"chose {chosen}, not {case.model}")
    out += [f"{k} {100 * row[k]:.3f} %" for k in ERRORS if row[k] > MAX_REL_ERROR]
    if not result.passed:
        out.append("gate: " + "; ".join(result.failures))
    return out


def tried(result: CalibrationResult) -> str:
    """Each model tried: its held-out error (px), or that it failed."""
    short = {"plumb_bob": "pb", "rational_polynomial": "rat", "equidistant": "eq"}
    parts = [f"{short.get(m, m)} {v:.3f}" for m, v in result.model_scores.items()]
    parts += [f"{short.get(m, m)} failed ({why})" for m, why in result.model_failures.items()]
    return ", ".join(parts)


@click.command("calib-synthetic", context_settings=CONTEXT, epilog=epilog())
@click.option("--case", "cases", type=click.Choice(list(CASES)), multiple=True,
              help="Cases to run (repeatable; default: all).")
def command(**params: Any) -> int:
    """The calibration tool on synthetic views through every lens model and board class, against the truth."""
    args = SimpleNamespace(**params)
    names = list(args.cases) or list(CASES)
    print(f"calibrate --images, lens model auto, every pair used; {SIZE[0]}x{SIZE[1]}, errors in % (worst of both "
          f"cameras), rot = rotation between the eyes vs truth (deg), rms / epi = stereo RMS / held-out epipolar (px), "
          f"tried = held-out error of each model (px)")
    print(f"load {' '.join(f'{v:.1f}' for v in os.getloadavg())}, {os.cpu_count()} CPUs, numpy {np.__version__}, "
          f"cv2 {cv2.__version__}")
    print(f"{'case':<44} {'chosen':<19} " + " ".join(f"{c:>8}" for c in (*ERRORS, "rot", "rms", "epi", "pairs", "secs"))
          + "  tried")
    failed = 0
    for name in names:
        case = CASES[name]
        t0 = time.perf_counter()
        head, pairs = head_and_pairs(case)
        try:
            result = calibrate(case, pairs)
        except (CalibrationError, ValueError) as exc:  # a case the tool cannot solve: a row, not the end
            failed += 1
            print(f"{name:<44} FAILED: {type(exc).__name__}: {exc}", flush=True)
            continue
        row = errors(result, head)
        missed = misses(case, result, row)
        failed += bool(missed)
        q = result.quality
        print(f"{name:<44} {result.calibration.lens_model:<19} " + " ".join(f"{100 * row[k]:8.3f}" for k in ERRORS)
              + f" {row['rot_deg']:8.3f} {q.rms_stereo:8.3f} {q.epipolar_rms_px:8.3f} {q.views_used:8d}"
              f" {time.perf_counter() - t0:8.1f}  {tried(result)}" + (f"  MISSED: {'; '.join(missed)}" if missed else ""),
              flush=True)
    print(f"targets: the case's lens model chosen (or one within the tie margin of its held-out error), fx, fy, cx, cy and baseline within {100 * MAX_REL_ERROR:.1f} % "
          f"of the truth, gate passed: {len(names) - failed} of {len(names)} cases MET")
    return 1 if failed else 0
