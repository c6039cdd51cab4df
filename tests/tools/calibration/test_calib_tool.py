"""Offline calibration tool end to end on rendered chessboard pairs with a known truth."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from stereocam.stereo.calibration_board import BoardSpec
from stereocam.device_sim.calibration.board import StereoBoardRenderer, board_poses
from stereocam.protocol.calibration import StereoCalibration
from stereocam.device_sim.calibration.truth import true_calibration
from stereocam.tools import cli
from stereocam.tools.calibration import calibrate
from stereocam.tools.calibration.solve import (
    BoardNotFoundError, CalibrationError, GateFailedError, SolveConfig, TooFewViewsError, calibrate_pairs,
    choose_detector, match_detections,
)
from stereocam.tools.calibration.coverage import CoverageSelector, view_params
from stereocam.tools.calibration.boards import detect_all

TRUTH = true_calibration(11, (640, 480))
BOARD = BoardSpec(9, 6, 0.03)
N_PAIRS = 24


@pytest.fixture(scope="module")
def pairs() -> list[tuple[np.ndarray, np.ndarray]]:
    renderer = StereoBoardRenderer(TRUTH, BOARD, supersample=1)
    rng = np.random.default_rng(5)
    return [renderer.render(p, rng) for p in board_poses(11, N_PAIRS, BOARD, TRUTH, distance_m=(0.35, 0.9))]


@pytest.fixture(scope="module")
def image_dir(tmp_path_factory: pytest.TempPathFactory, pairs) -> Path:
    d = tmp_path_factory.mktemp("pairs")
    for i, (left, right) in enumerate(pairs):
        cv2.imwrite(str(d / f"left_{i:03d}.png"), left)
        cv2.imwrite(str(d / f"right{i}.png"), right)
    (d / "notes.txt").write_text("ignored")
    return d


def run(image_dir: Path, out: Path, *extra: str) -> int:
    return cli.main(["calibrate", "-q", "--images", str(image_dir), "--board", "9x6", "--square-size", "0.03",
                           "--out", str(out), *extra])


def test_offline_calibration_recovers_truth(image_dir: Path, tmp_path: Path) -> None:
    assert run(image_dir, tmp_path) == 0
    d = json.loads((tmp_path / "calibration.json").read_text())
    assert d["passed"] is True and d["written"] is False and d["verified"] is False
    assert d["views_used"] >= 8 and d["rms_stereo"] < 0.2 and d["epipolar_rms_px"] < 0.15
    c = StereoCalibration.from_json_dict(d)
    for got, true in ((c.K_left, TRUTH.K_left), (c.K_right, TRUTH.K_right)):
        np.testing.assert_allclose(got[[0, 1, 0, 1], [0, 1, 2, 2]], true[[0, 1, 0, 1], [0, 1, 2, 2]], rtol=6e-3)
    assert abs(c.baseline_m / TRUTH.baseline_m - 1) < 5e-3
    fs = cv2.FileStorage(str(tmp_path / "calibration.yaml"), cv2.FILE_STORAGE_READ)
    np.testing.assert_allclose(fs.getNode("T").mat().ravel(), c.T, rtol=1e-12)
    assert fs.getNode("P2").mat().shape == (3, 4) and fs.getNode("Q").mat().shape == (4, 4)
    left = (tmp_path / "left.yaml").read_text()
    assert "distortion_model: plumb_bob" in left and "image_width: 640" in left and "projection_matrix:" in left
    assert cv2.imread(str(tmp_path / "report.png")).shape[1] == 1280


def test_metric_definitions(pairs) -> None:
    res = calibrate_pairs(iter(pairs), BOARD, select=False)
    used = [v for v in res.views if v.status == "used"]
    held = [v for v in res.views if v.held_out]
    assert len(used) == res.quality.views_used == N_PAIRS - res.quality.views_dropped
    assert [v.index for v in held] == [v.index for v in used][4::5]      # every 5th pair kept
    # per-camera RMS = sqrt(mean over all corners of squared 2-D distance) = pooled per-view RMS
    assert res.quality.rms_left == pytest.approx(np.sqrt(np.mean([v.rms_left ** 2 for v in used])), rel=1e-9)
    # all-pairs epipolar RMS: recompute from scratch with the stored geometry, converged undistortion
    c, r = res.calibration, res.rectification
    dy = []
    found = [(v.index, v.label, *(detect_all(img, BOARD) for img in pairs[v.index])) for v in used]
    order = choose_detector(found, c.image_size)  # the detectors the solver used for the set
    for _, _, dl, dr in found:
        _, cl, cr = match_detections(dl, dr, BOARD, order)
        crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-12)
        yl = cv2.undistortPoints(cl.reshape(-1, 1, 2).astype(float), c.K_left, c.D_left,
                                 R=r.R1, criteria=crit)[:, 0, 1]
        yr = cv2.undistortPoints(cr.reshape(-1, 1, 2).astype(float), c.K_right, c.D_right,
                                 R=r.R2, criteria=crit)[:, 0, 1]
        dy.append(c.K_left[1, 1] * (np.arctan(yl) - np.arctan(yr)))  # the epipolar planes' angle, raw px
    assert res.quality.epipolar_all_rms_px == pytest.approx(np.sqrt(np.mean(np.concatenate(dy) ** 2)), rel=1e-6)
    assert res.calibration.lens_model == "plumb_bob"  # the simulated lenses are plumb_bob: simpler wins


def test_non_simultaneous_pairs_are_found_and_named(pairs) -> None:
    """Two right images from the neighbouring pair: the stereo/epipolar residuals single them out."""
    bad = list(pairs)
    bad[3] = (pairs[3][0], pairs[4][1])
    bad[11] = (pairs[11][0], pairs[12][1])
    res = calibrate_pairs(iter(bad), BOARD, select=False)
    assert sorted(v.index for v in res.dropped) == [3, 11]
    assert all(("stereo" in v.reason or "epipolar" in v.reason) for v in res.dropped)
    assert res.passed


def test_forced_lens_model(pairs) -> None:
    res = calibrate_pairs(iter(pairs), BOARD, SolveConfig(lens_model="rational_polynomial"), select=False)
    assert res.calibration.lens_model == "rational_polynomial" and len(res.calibration.D_left) == 8
    assert list(res.model_scores) == ["rational_polynomial"]


def test_gate_failure_writes_nothing_as_passed(image_dir: Path, tmp_path: Path, capsys) -> None:
    (tmp_path / "left.yaml").write_text("stale")
    assert run(image_dir, tmp_path, "--max-stereo-rms", "0.01", "--lens-model", "plumb_bob") == calibrate.EXIT_GATE
    assert "FAILED the gate: stereo RMS" in capsys.readouterr().err
    assert json.loads((tmp_path / "calibration.json").read_text())["passed"] is False
    assert not any((tmp_path / n).exists() for n in ("left.yaml", "right.yaml", "calibration.yaml"))
    assert (tmp_path / "report.png").exists()


@pytest.mark.parametrize("n, model", [(10, "plumb_bob"), (14, "auto")])
def test_mismatched_pairs_fail_the_gate(pairs, n: int, model: str) -> None:
    """Right images shifted by one pair: the solve 'converges' but the stereo RMS exposes it.
    At most fourteen pairs: on mismatched pairs every stereo solve runs to its iteration cap, and on
    24 pairs the fit took ~50 s on a loaded machine. On 10-12 such pairs the fits may not rectify at
    all (the relative pose is nonsense): the gate's verdict then comes as GateFailedError, with the
    same evidence (10 pairs, plumb_bob: "rectification gives no usable view")."""
    few = pairs[:n]
    shifted = [(few[i][0], few[(i + 1) % len(few)][1]) for i in range(len(few))]
    try:
        failures = calibrate_pairs(iter(shifted), BOARD, SolveConfig(lens_model=model), select=False).failures
    except GateFailedError as exc:
        failures = exc.failures
        assert any(f.startswith("no usable rectification: ") for f in failures), failures
    assert any(f.startswith("stereo RMS") and float(f.split()[2]) > 10 for f in failures), failures


def test_board_never_found(tmp_path: Path, capsys) -> None:
    blank = np.full((480, 640), 100, np.uint8)
    for i in range(3):
        cv2.imwrite(str(tmp_path / f"left{i}.png"), blank)
        cv2.imwrite(str(tmp_path / f"right{i}.png"), blank)
    out = tmp_path / "out"
    assert run(tmp_path, out) == calibrate.EXIT_NO_SOLUTION
    assert "board was not found in both images of any of the 3 pairs" in capsys.readouterr().err
    assert not out.exists()
    with pytest.raises(BoardNotFoundError):
        calibrate_pairs(iter([(blank, blank)]), BOARD)


def test_too_few_views(pairs, image_dir: Path, tmp_path: Path) -> None:
    with pytest.raises(TooFewViewsError, match="need 8"):
        calibrate_pairs(iter(pairs[:6]), BOARD)                      # live capture: distinct views
    with pytest.raises(TooFewViewsError, match="need 5"):
        calibrate_pairs(iter(pairs[:4]), BOARD, select=False)        # offline: pairs, alike or not
    small = tmp_path / "small"
    small.mkdir()
    for p in sorted(image_dir.glob("*_00[0-3].png")) + [image_dir / f"right{i}.png" for i in range(4)]:
        shutil.copy(p, small)
    assert run(small, tmp_path / "out") == calibrate.EXIT_NO_SOLUTION
    assert not (tmp_path / "out").exists()


def test_engine_stops_reading_when_enough(pairs) -> None:
    consumed = []

    def stream():
        for i, p in enumerate(pairs * 3):
            consumed.append(i)
            yield p

    res = calibrate_pairs(stream(), BOARD, SolveConfig(max_views=8))
    held = sum(v.held_out for v in res.views)
    assert res.quality.views_used - held == 8 and len(consumed) < 3 * len(pairs)


def test_bad_arguments(image_dir: Path, tmp_path: Path, capsys) -> None:
    assert run(image_dir, tmp_path, "--holdout-every", "1") == calibrate.EXIT_USAGE
    assert cli.main(["calibrate", "--images", str(image_dir), "--board", "9x6", "--square-size", "25",
                           "--out", str(tmp_path)]) == calibrate.EXIT_USAGE
    assert "metres" in capsys.readouterr().err
    assert cli.main(["calibrate", "--images", str(image_dir), "--board", "9by6", "--square-size", "0.03",
                           "--out", "x"]) == calibrate.EXIT_USAGE
    capsys.readouterr()
    assert cli.main(["calibrate", "--images", str(image_dir), "--board", "aprilgrid:6x6:0.05",
                           "--out", str(tmp_path)]) == calibrate.EXIT_USAGE
    assert "aprilgrid:COLSxROWS:TAG_SIZE:SPACING" in capsys.readouterr().err
    assert cli.main(["calibrate", "--images", str(image_dir), "--board", str(tmp_path / "target.yaml"),
                           "--out", str(tmp_path)]) == calibrate.EXIT_USAGE  # no --square-size needed: its own
    assert "cannot read the target yaml" in capsys.readouterr().err


def test_find_pairs_rules(tmp_path: Path) -> None:
    for name in ("left1.png", "right01.png", "LEFT_2.jpg", "right-2.png", "left3.png", "right.png"):
        (tmp_path / name).write_bytes(b"")
    assert [(n, l.name, r.name) for n, l, r in calibrate.find_pairs(tmp_path)] == [
        (1, "left1.png", "right01.png"), (2, "LEFT_2.jpg", "right-2.png")]
    (tmp_path / "left001.png").write_bytes(b"")
    with pytest.raises(ValueError, match="two left images with number 1"):
        calibrate.find_pairs(tmp_path)
    with pytest.raises(ValueError, match="is not a directory"):
        calibrate.find_pairs(tmp_path / "left3.png")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="no left<N>/right<N>"):
        calibrate.find_pairs(empty)


def test_view_params_and_selector() -> None:
    w, h = 640, 480
    j, i = np.mgrid[0:6, 0:9]
    centred = np.column_stack([320 + (i.ravel() - 4) * 30, 240 + (j.ravel() - 2.5) * 30]).astype(np.float32)
    x, y, size, skew = view_params(centred, BOARD, (w, h))
    assert x == pytest.approx(0.5) and y == pytest.approx(0.5) and skew == pytest.approx(0.0, abs=1e-9)
    assert size == pytest.approx(np.sqrt(240 * 150 / (w * h)))
    sel = CoverageSelector(0.2)
    assert sel.offer((0.5, 0.5, 0.3, 0.0)) and not sel.offer((0.55, 0.55, 0.3, 0.05))
    assert sel.offer((0.9, 0.5, 0.3, 0.0))
    assert sel.coverage() == pytest.approx((0.4 / 0.7, 0.0, 0.0, 0.0))


def test_solver_failure_is_a_calibration_error(pairs, monkeypatch) -> None:
    def broken(*args, **kwargs):
        raise cv2.error("simulated solver breakdown")

    monkeypatch.setattr(cv2, "calibrateCameraExtended", broken)
    monkeypatch.setattr(cv2.fisheye, "calibrate", broken)
    with pytest.raises(CalibrationError, match="solver failed on .* pairs: .*simulated"):
        calibrate_pairs(iter(pairs), BOARD)


def test_a_failed_lens_model_is_listed_and_another_one_fits(pairs, monkeypatch) -> None:
    def broken(*args, **kwargs):
        raise cv2.error("simulated solver breakdown")

    monkeypatch.setattr(cv2, "calibrateCameraExtended", broken)  # plumb_bob and rational: no fit at all
    res = calibrate_pairs(iter(pairs), BOARD, select=False)
    assert res.calibration.lens_model == "equidistant" and list(res.model_scores) == ["equidistant"]
    assert set(res.model_failures) == {"plumb_bob", "rational_polynomial"}
    assert "simulated" in res.model_failures["plumb_bob"]


def test_offline_run_shows_pairs_done_of_total_even_when_quiet(tmp_path):
    """Issue 14: progress with N/total and rate on stderr; -q keeps only the bar, never silence."""
    import subprocess
    import sys

    from tests.support.paths import DATA

    def run(*extra):
        return subprocess.run([sys.executable, "-m", "stereocam.tools.cli", "calibrate", "--images",
                               str(DATA / "opencv_chessboard_pairs"), "--board", "9x6", "--square-size", "0.025",
                               "--out", str(tmp_path / f"out{len(extra)}"), "--db", str(tmp_path / "f.sqlite"),
                               "--lens-model", "plumb_bob", *extra], capture_output=True, text=True, timeout=600)

    loud, quiet = run(), run("-q")
    assert loud.returncode == quiet.returncode == 0, loud.stderr + quiet.stderr
    assert "13/13" in loud.stderr and "13/13" in quiet.stderr  # pairs done of total
    assert "pair/s" in quiet.stderr or "s/pair" in quiet.stderr
    assert loud.stdout.count(" kept ") == 13 and " kept " not in quiet.stdout


@pytest.mark.parametrize("left, right", [
    ("L01.png", "R01.png"), ("img_L_7.png", "img_R_7.png"), ("imgL3.png", "imgR3.png"),
    ("cam_left-0003.png", "cam_right-0003.png"), ("stereoLeft12.jpg", "stereoRight12.jpg"),
    ("left/0005.png", "right/0005.png"), ("cam0/frame_0009.png", "cam1/frame_0009.png"),
    ("L/a.png", "R/a.png"),
])
def test_real_sets_name_their_pairs_many_ways(tmp_path: Path, left: str, right: str) -> None:
    for name in (left, right, "bright_01.png", "pair03.png", "frame5.png"):  # the last three name no side
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes(b"")
    pairs = calibrate.find_pairs(tmp_path)
    assert [(l.relative_to(tmp_path).as_posix(), r.relative_to(tmp_path).as_posix()) for _, l, r in pairs] == [
        (left, right)]
