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

import pytest

from tests.support.paths import REPO, SHARED_DATA

from stereocam.protocol.calibration import StereoCalibration
from stereocam.tools.bench.calib_real import SETS as BENCH_SETS
from stereocam.tools.bench.calib_real import epipolar_all, opencv_all_pairs

SHARED = Path(os.environ.get("STEREOCAM_CALIB_SETS", SHARED_DATA / "calibration"))
SETS = {name: ((REPO if name == "opencv_pairs" else SHARED) / folder, board, square)
        for name, (folder, board, square) in BENCH_SETS.items()}


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
