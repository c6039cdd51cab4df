"""Real calibration sets against OpenCV's own solution: the issue-10 "done when" table.

For each set: `stereocam calibrate --images DIR --board ... --square-size ...` with no other option
(in-process, its factory record in a temporary file), and OpenCV's solution on every pair where both boards are found —
cv2.calibrateCamera per camera and cv2.stereoCalibrate with fixed intrinsics, with the lens model
the tool chose and the same corner detections. Reported: model chosen and every model tried (its
held-out score, or why it failed), pairs used/dropped (with the reasons), pairs that look
unsynchronised, focal (left, right) and baseline relative error, and epipolar RMS of both solutions
over all those pairs (converged undistortion, each solution's own rectification).

    stereocam bench calib-real [--sets DIR] [--only NAME]
"""
from __future__ import annotations

import contextlib
import io
import json
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any, cast

import click
import cv2
import numpy as np

from stereocam.protocol.calibration import N_DIST, StereoCalibration
from stereocam.protocol.rectification import stereo_rectify
from stereocam.tools import cli
from stereocam.tools.calibration.board_text import parse_board
from stereocam.tools.calibration.boards import detect_all
from stereocam.tools.calibration.files import find_pairs
from stereocam.tools.calibration.fit import HeadFit, PairPoints, epipolar_dy, rms
from stereocam.tools.calibration.lens import SOLVE, calibrate_mono, calibrate_stereo
from stereocam.tools.calibration.solve import choose_detector, match_detections
from stereocam.tools.options import CONTEXT, epilog

SETS = {  # name: (folder relative to the sets folder, or to the repository for OpenCV's pairs, board, square)
    "opencv_pairs": ("tests/data/opencv_chessboard_pairs", "9x6", "0.025"),
    "bumblebee2": ("boofcv_bumblebee2_chess", "6x4", "0.03"),
    "trinocular_ecocheck": ("boofcv_trinocular_ecocheck", "13x9", "1"),
    "davinci_charuco": ("sksurgery_davinci_charuco", "charuco:19x26:0.005:0.004:DICT_4X4_250", None),
}


class _Head:
    """What epipolar_dy needs of a fit: the calibration and its rectification."""

    def __init__(self, calibration: StereoCalibration) -> None:
        self.calibration, self.geometry = calibration, stereo_rectify(calibration)


def opencv_all_pairs(directory: Path, board_text: str, square: str | None, model: str
                     ) -> tuple[StereoCalibration, list[PairPoints]]:
    """OpenCV's solution on every pair where both boards are found (same detections as the tool)."""
    board = parse_board(board_text, None if square is None else float(square))
    found = []
    size = (0, 0)
    for n, lp, rp in find_pairs(directory):
        left, right = _gray(lp), _gray(rp)
        size = left.shape[::-1]
        dl, dr = detect_all(left, board), detect_all(right, board)
        if match_detections(dl, dr, board, ()) is not None:
            found.append((n, lp.name, dl, dr))
    order = choose_detector(found, size)
    pairs = []
    for n, name, dl, dr in found:
        matched = match_detections(dl, dr, board, order)
        if matched is None:
            raise click.ClickException(f"{directory}: pair {name}: no corners of the chosen detectors {order}")
        pairs.append(PairPoints(n, name, *matched))
    obj = [p.obj for p in pairs]
    if model == "equidistant":  # cv2.fisheye has no cold start that converges reliably: seed it as the tool does
        fl, fr = (calibrate_mono(model, obj, pts, size, calibrate_mono("plumb_bob", obj, pts, size))
                  for pts in ([p.left for p in pairs], [p.right for p in pairs]))
        st = calibrate_stereo(model, obj, [p.left for p in pairs], [p.right for p in pairs], size, fl, fr)
        K1, D1, K2, D2, R, T = fl.K, fl.D, fr.K, fr.D, st.R, st.T
    else:
        flags = cv2.CALIB_RATIONAL_MODEL if model == "rational_polynomial" else 0
        o = [np.asarray(x, np.float32) for x in obj]
        L, Rp = ([np.asarray(getattr(p, s), np.float32).reshape(-1, 1, 2) for p in pairs] for s in ("left", "right"))
        _, K1, D1, *_ = cv2.calibrateCamera(o, L, size, None, None, flags=flags, criteria=SOLVE)
        _, K2, D2, *_ = cv2.calibrateCamera(o, Rp, size, None, None, flags=flags, criteria=SOLVE)
        *_, R, T, _, _ = cv2.stereoCalibrate(o, L, Rp, K1, D1, K2, D2, size, flags=flags | cv2.CALIB_FIX_INTRINSIC,
                                             criteria=SOLVE)
    n = N_DIST[model]
    return StereoCalibration(size, K1, np.ravel(D1)[:n], K2, np.ravel(D2)[:n], R, np.ravel(T), model), pairs


def _gray(path: Path) -> np.ndarray:
    """An image file as grey levels; a ClickException naming a file OpenCV cannot read."""
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise click.ClickException(f"{path}: not an image OpenCV can read")
    return img


def epipolar_all(calibration: StereoCalibration, pairs: list[PairPoints]) -> float:
    """Epipolar RMS (px) of a solution over every pair."""
    head = cast(HeadFit, _Head(calibration))  # epipolar_dy reads only .calibration and .geometry
    return rms(np.concatenate([epipolar_dy(head, p.left, p.right) for p in pairs]))


def compare(directory: Path, board: str, square: str | None, out: Path) -> dict:
    """Run the tool as a user would and compare it with OpenCV's all-pairs solution."""
    argv = ["-q", "--images", str(directory), "--board", board, "--out", str(out), "--db", str(out / "f.sqlite")]
    with contextlib.redirect_stdout(io.StringIO()):
        code = cli.main(["calibrate", *argv, *([] if square is None else ["--square-size", square])])
    doc = json.loads((out / "calibration.json").read_text())
    mine = StereoCalibration.from_json_dict(doc)
    ref, pairs = opencv_all_pairs(directory, board, square, mine.lens_model)
    return {"exit": code, "doc": doc, "pairs": len(pairs),
            "fx_left": mine.K_left[0, 0] / ref.K_left[0, 0] - 1, "fx_right": mine.K_right[0, 0] / ref.K_right[0, 0] - 1,
            "baseline": mine.baseline_m / ref.baseline_m - 1,
            "epi_mine": epipolar_all(mine, pairs), "epi_opencv": epipolar_all(ref, pairs),
            "fx": mine.K_left[0, 0], "baseline_m": mine.baseline_m}


@click.command("calib-real", context_settings=CONTEXT, epilog=epilog())
@click.option("--sets", type=click.Path(file_okay=False, path_type=Path), default=Path("../shared/data/calibration"),
              show_default=True, help="The shared sets folder.")
@click.option("--only", type=click.Choice(list(SETS)), multiple=True, help="Run only these sets (repeatable).  [default: all]")
def command(**params: Any) -> int:
    """Real calibration sets against OpenCV's own all-pairs solution, with the done-when targets."""
    args = SimpleNamespace(**params)
    print(f"{'set':<20} {'exit':>4} {'model':<20} {'used':>4} {'drop':>4} {'fxL %':>7} {'fxR %':>7} "
          f"{'base %':>7} {'epi px':>7} {'cv epi':>7} {'time s':>6}")
    ok = True
    for name in args.only or SETS:
        folder, board, square = SETS[name]
        directory = Path(folder) if name == "opencv_pairs" else args.sets / folder
        if not directory.is_dir():
            print(f"{name:<20} skipped: {directory} absent")
            continue
        t0 = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp:
            r = compare(directory, board, square, Path(tmp))
        d = r["doc"]
        print(f"{name:<20} {r['exit']:>4} {d['lens_model']:<20} {d['views_used']:>4} {d['views_dropped']:>4} "
              f"{100 * r['fx_left']:>7.3f} {100 * r['fx_right']:>7.3f} {100 * r['baseline']:>7.3f} "
              f"{r['epi_mine']:>7.3f} {r['epi_opencv']:>7.3f} {time.perf_counter() - t0:>6.1f}")
        tried = [f"{m} {score:.3f}" for m, score in d["lens_model_scores"].items()]
        tried += [f"{m} failed ({why})" for m, why in d.get("lens_model_failures", {}).items()]
        print(f"{'':<20} models tried (held-out score px): {'; '.join(tried)}")
        if d.get("unsynchronised_pairs"):
            print(f"{'':<20} unsynchronised: {', '.join(u['pair'] for u in d['unsynchronised_pairs'])}")
        for drop in d["dropped"]:
            print(f"{'':<20} dropped {drop['pair']}: {drop['reason']}")
        ok &= r["exit"] == 0 and max(abs(r[k]) for k in ("fx_left", "fx_right", "baseline")) <= 0.005 \
            and r["epi_mine"] <= r["epi_opencv"] + 0.05
    print("done-when (exit 0, focal and baseline within 0.5 %, epipolar <= OpenCV's + 0.05 px): "
          + ("MET" if ok else "MISSED"))
    return 0 if ok else 1

