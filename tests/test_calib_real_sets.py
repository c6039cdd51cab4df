"""Offline calibration on real rigs, run as a user would (no option beyond board and square size),
compared with OpenCV's own solution on every pair (cv2.calibrateCamera + cv2.stereoCalibrate with
fixed intrinsics, the lens model the tool chose, the same corner detections).

The three shared sets live in ../shared/data/calibration (beside the clone in CI); OpenCV's 13
sample pairs are in tests/data. STEREOCAM_CALIB_SETS names another folder holding the three sets.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from stereocam.tools import calibrate
from stereocam.tools.calib_boards import parse_board
from stereocam.tools.calib_fit import PairPoints, epipolar_dy, rms
from stereocam.tools.calib_lens import SOLVE, calibrate_mono
from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.rectification import stereo_rectify
from stereocam.tools.calib_solve import _match, choose_detector, detect_all

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("STEREOCAM_CALIB_SETS", REPO.parent / "shared" / "data" / "calibration"))
SETS = {
    "opencv_pairs": (REPO / "tests" / "data" / "opencv_chessboard_pairs", "9x6", "0.025"),
    "bumblebee2": (SHARED / "boofcv_bumblebee2_chess", "6x4", "0.03"),
    "trinocular_ecocheck": (SHARED / "boofcv_trinocular_ecocheck", "13x9", "1"),
    "davinci_charuco": (SHARED / "sksurgery_davinci_charuco", "charuco:19x26:0.005:0.004:DICT_4X4_250", None),
}


class _Head:
    """Just enough of a HeadFit for epipolar_dy."""

    def __init__(self, calibration: StereoCalibration) -> None:
        self.calibration, self.geometry = calibration, stereo_rectify(calibration)


def opencv_all_pairs(directory: Path, board_text: str, square: str | None, model: str) -> tuple[
        StereoCalibration, list[PairPoints]]:
    """OpenCV's solution on every pair where both boards are found (same detections as the tool)."""
    board = parse_board(board_text, None if square is None else float(square))
    found = []
    for n, lp, rp in calibrate.find_pairs(directory):
        dl, dr = (detect_all(cv2.imread(str(p), cv2.IMREAD_GRAYSCALE), board) for p in (lp, rp))
        if _match(dl, dr, board, ()) is not None:
            found.append((n, lp.name, dl, dr))
    size = cv2.imread(str(lp), cv2.IMREAD_GRAYSCALE).shape[::-1]
    order = (choose_detector(found, size),)
    pairs = [PairPoints(n, name, *_match(dl, dr, board, order)) for n, name, dl, dr in found]
    obj = [p.obj for p in pairs]
    if model == "equidistant":
        fl, fr = (calibrate_mono(model, obj, [getattr(p, s) for p in pairs], size,
                                 calibrate_mono("plumb_bob", obj, [getattr(p, s) for p in pairs], size))
                  for s in ("left", "right"))
        o = [np.asarray(x, np.float64).reshape(1, -1, 3) for x in obj]
        L, R = ([np.asarray(getattr(p, s), np.float64).reshape(1, -1, 2) for p in pairs] for s in ("left", "right"))
        flags = getattr(cv2.fisheye, "CALIB_FIX_INTRINSIC", None) or cv2.CALIB_FIX_INTRINSIC
        out = cv2.fisheye.stereoCalibrate(o, L, R, fl.K, fl.D, fr.K, fr.D, size, flags=flags, criteria=SOLVE)
        K1, D1, K2, D2, Rm, T = fl.K, fl.D, fr.K, fr.D, out[5], out[6]
    else:
        flags = cv2.CALIB_RATIONAL_MODEL if model == "rational_polynomial" else 0
        L, R = ([np.asarray(getattr(p, s), np.float32).reshape(-1, 1, 2) for p in pairs] for s in ("left", "right"))
        o = [np.asarray(x, np.float32) for x in obj]
        _, K1, D1, *_ = cv2.calibrateCamera(o, L, size, None, None, flags=flags, criteria=SOLVE)
        _, K2, D2, *_ = cv2.calibrateCamera(o, R, size, None, None, flags=flags, criteria=SOLVE)
        *_, Rm, T, _, _ = cv2.stereoCalibrate(o, L, R, K1, D1, K2, D2, size, flags=flags | cv2.CALIB_FIX_INTRINSIC,
                                              criteria=SOLVE)
    n = {"plumb_bob": 5, "rational_polynomial": 8, "equidistant": 4}[model]
    return StereoCalibration(size, K1, D1.ravel()[:n], K2, D2.ravel()[:n], Rm, np.ravel(T), model), pairs


def epipolar_all(calibration: StereoCalibration, pairs: list[PairPoints]) -> float:
    head = _Head(calibration)
    return rms(np.concatenate([epipolar_dy(head, p.left, p.right) for p in pairs]))


@pytest.mark.parametrize("name", list(SETS))
def test_real_set_passes_with_defaults_and_matches_opencv(name: str, tmp_path: Path) -> None:
    directory, board, square = SETS[name]
    if not directory.is_dir():
        pytest.skip(f"{directory} is absent (the shared calibration sets sit beside the clone)")
    cmd = [sys.executable, "-m", "stereocam.tools.cli", "calibrate", "--images", str(directory), "--board", board,
           "--out", str(tmp_path)] + ([] if square is None else ["--square-size", square])
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr
    doc = json.loads((tmp_path / "calibration.json").read_text())
    assert doc["passed"] is True and doc["lens_model"] in doc["lens_model_scores"]
    for d in doc["dropped"]:  # every dropped pair is named with its reason, on stdout too
        assert d["reason"] and f"dropped {d['pair']}: {d['reason']}" in r.stdout
    mine = StereoCalibration.from_json_dict(doc)
    ref, pairs = opencv_all_pairs(directory, board, square, mine.lens_model)
    assert doc["views_used"] + doc["views_dropped"] == len(pairs)
    assert abs(mine.K_left[0, 0] / ref.K_left[0, 0] - 1) < 0.005
    assert abs(mine.K_right[0, 0] / ref.K_right[0, 0] - 1) < 0.005
    assert abs(mine.baseline_m / ref.baseline_m - 1) < 0.005
    assert epipolar_all(mine, pairs) <= epipolar_all(ref, pairs) + 0.05
    ros = (tmp_path / "left.yaml").read_text()
    assert f"distortion_model: {mine.lens_model}" in ros
