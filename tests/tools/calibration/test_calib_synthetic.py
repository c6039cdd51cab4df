"""The calibration tool on rendered board views with known truth (device_sim/calibration/lens_views.py):
every lens model and board class, from image pixels to the chosen model and recovered geometry."""
from __future__ import annotations

import re
from functools import cache
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from stereocam.tools.calibration.board_text import parse_board
from stereocam.tools.calibration.boards import AprilGridSpec, CharucoSpec, Detection, match_pair
from stereocam.tools.calibration.fit import PairPoints, UnrectifiableFitError, fit_head
from stereocam.tools.calibration.lens import calibrate_mono, calibrate_stereo
from stereocam.tools.calibration.outputs import write_outputs
from stereocam.tools.calibration.solve import CalibrationResult, SolveConfig, calibrate_pairs
from stereocam.stereo.calibration_board import BoardSpec
from stereocam.device_sim.calibration import lens_views as synth
from stereocam.tools.bench import calib_synthetic as bench

SIZE = bench.SIZE
TRUTH_TOLERANCE = bench.MAX_REL_ERROR  # the 0.2 %

# the cases of `stereocam bench calib-synthetic` that the suite runs: one per lens model and board class
CASES = ["plumb_bob 70deg chessboard 9x6", "plumb_bob 60deg chessboard 7x7 any roll", "rational 130deg chessboard 9x6",
         "equidistant 150deg chessboard 9x6", "plumb_bob 70deg charuco legacy",
         "plumb_bob 70deg charuco current inverted", "rational 130deg charuco current",
         "equidistant 150deg aprilgrid 4x3"]


@cache
def _views(case: str) -> tuple[synth.Rig, list[tuple[np.ndarray, np.ndarray]]]:
    return bench.head_and_pairs(bench.CASES[case])


@cache
def _result(case: str) -> CalibrationResult:
    return bench.calibrate(bench.CASES[case], _views(case)[1])


def _assert_truth(result: CalibrationResult, head: synth.Rig) -> None:
    row = bench.errors(result, head)
    assert max(row[k] for k in bench.ERRORS) <= TRUTH_TOLERANCE, row
    assert row["rot_deg"] < 0.1, row


@pytest.mark.slow
@pytest.mark.parametrize("case", CASES)
def test_each_lens_and_board_class_gives_the_right_model_and_the_truth(case: str) -> None:
    head, _ = _views(case)
    result = _result(case)
    assert bench.misses(bench.CASES[case], result, bench.errors(result, head)) == [], \
        (result.model_scores, result.model_failures)
    _assert_truth(result, head)
    assert result.quality.views_used >= 10
    assert result.sync is not None and not result.sync.suspects


def _corners(board: BoardSpec | CharucoSpec | AprilGridSpec, pairs) -> tuple[list, list, list]:
    from stereocam.tools.calibration.boards import detect_all

    obj, left, right = [], [], []
    for l, r in pairs:
        dl, dr = detect_all(l, board), detect_all(r, board)
        if dl and dr:
            o, pl, pr = match_pair(next(iter(dl.values())), next(iter(dr.values())), board)
            obj.append(o), left.append(pl), right.append(pr)
    return obj, left, right


@pytest.mark.slow
def test_a_190_degree_fisheye_is_fitted_through_cv2_fisheye_from_a_sound_start() -> None:
    """Mono and stereo fits of the equidistant model (the rectification the camera stores is not
    part of this: SPEC §12.6); the views reach 85 degrees off axis."""
    head = synth.rig("equidistant", 190, SIZE)
    pairs = synth.stereo_views(head, synth.chessboard(9, 6, 0.03), 12, seed=5, distance=(0.15, 0.35), reach=0.9)
    obj, left, right = _corners(BoardSpec(9, 6, 0.03), pairs)
    assert len(obj) >= 10
    fl = calibrate_mono("equidistant", obj, left, SIZE)
    fr = calibrate_mono("equidistant", obj, right, SIZE)
    st = calibrate_stereo("equidistant", obj, left, right, SIZE, fl, fr)
    assert fl.rms < 0.15 and st.rms < 0.2
    assert abs(fl.K[0, 0] / head.left.K[0, 0] - 1) < TRUTH_TOLERANCE
    assert abs(fr.K[1, 1] / head.right.K[1, 1] - 1) < TRUTH_TOLERANCE
    assert abs(np.linalg.norm(st.T) / np.linalg.norm(head.T) - 1) < TRUTH_TOLERANCE


@pytest.mark.slow
def test_a_rational_head_whose_full_fit_folds_beyond_the_views_gets_a_reduced_rational_fit() -> None:
    """A 110 degree rational lens seen to 0.9 of its half-width: every full 8-coefficient fit matches
    the training pairs' corners and turns back beyond them (the rectification folds), so the model
    was lost to the choice; held at k3 = k6 = 0 (lens.RATIONAL_REDUCED) it rectifies and still meets the truth."""
    case = bench.CASES["rational 110deg chessboard 9x6"]
    head, pairs = _views("rational 110deg chessboard 9x6")
    obj, left, right = _corners(parse_board(case.board, bench.SQUARE_M), pairs)
    points = [PairPoints(i, str(i), o, pl, pr) for i, (o, pl, pr) in enumerate(zip(obj, left, right))]
    every = SolveConfig().holdout_every
    points = [p for p in points if p.index % every != every - 1]  # the tool's training pairs
    with pytest.raises(UnrectifiableFitError, match="folds"):
        fit_head("rational_polynomial", points, SIZE, reduce=False)
    fit = fit_head("rational_polynomial", points, SIZE)
    c = fit.calibration
    assert c.lens_model == "rational_polynomial"
    for D in (c.D_left, c.D_right):
        assert D[4] == 0 and D[7] == 0 and np.all(D[[0, 5]] != 0)  # k3, k6 held; k1, k4 fitted
    for K, true in ((c.K_left, head.left.K), (c.K_right, head.right.K)):
        assert abs(K[0, 0] / true[0, 0] - 1) < TRUTH_TOLERANCE and abs(K[1, 1] / true[1, 1] - 1) < TRUTH_TOLERANCE
    assert abs(c.baseline_m / float(np.linalg.norm(head.T)) - 1) < TRUTH_TOLERANCE


def test_square_board_numbering_follows_the_left_view_whatever_the_detector_did() -> None:
    board = BoardSpec(4, 4, 0.03)
    grid = np.array([[10 + 20 * i, 50 + 20 * j] for j in range(4) for i in range(4)], np.float32)
    left = Detection(np.arange(16), grid, board.object_points())
    for order in (np.rot90(np.arange(16).reshape(4, 4)).ravel(), np.arange(16).reshape(4, 4).T.ravel(),
                  np.arange(16)[::-1]):
        right = Detection(np.arange(16), grid[order] + [-30.0, 0.5], board.object_points())
        _, l, r = match_pair(left, right, board)
        np.testing.assert_allclose(r - l, np.tile([-30.0, 0.5], (16, 1)))


def test_board_texts_and_kalibr_target_files(tmp_path: Path) -> None:
    assert parse_board("6x6", 0.02) == BoardSpec(6, 6, 0.02)
    grid = parse_board("aprilgrid:6x6:0.088:0.3", None)
    assert isinstance(grid, AprilGridSpec) and (grid.cols, grid.rows, grid.tag_m, grid.spacing) == (6, 6, 0.088, 0.3)
    # Kalibr's points: tag 7 of a 6-wide grid is row 1, col 1: its bottom-left at (1.3, 1.3) tag sizes
    bl = grid.object_points()[grid.point_ids(7)[3]]
    np.testing.assert_allclose(bl, [1.3 * 0.088, 1.3 * 0.088, 0.0], rtol=1e-6)
    target = tmp_path / "april_6x6.yaml"
    target.write_text("target_type: 'aprilgrid'\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\n")
    assert parse_board(str(target), None) == grid
    checker = tmp_path / "checker.yaml"
    checker.write_text("target_type: 'checkerboard'\ntargetCols: 7\ntargetRows: 6\n"
                       "rowSpacingMeters: 0.06\ncolSpacingMeters: 0.06\n")
    assert parse_board(str(checker), None) == BoardSpec(7, 6, 0.06)
    checker.write_text("target_type: 'circlegrid'\n")
    with pytest.raises(ValueError, match="not supported"):
        parse_board(str(checker), None)


@pytest.mark.slow
def test_unsynchronised_pairs_are_reported_with_the_evidence() -> None:
    case = bench.CASES["plumb_bob 70deg chessboard 9x6"]
    head = synth.rig(case.model, case.fov, SIZE)
    pairs = synth.stereo_views(head, case.texture(), 14, seed=3, distance=(0.2, 0.5), late=(2, 6, 11))
    result = calibrate_pairs(iter(pairs), parse_board(case.board, 0.03), SolveConfig(),
                             labels=[f"p{i}" for i in range(14)], select=False)
    suspects = result.sync.suspects
    assert sorted(p.label for p in suspects) == ["p11", "p2", "p6"]
    assert all(1.0 < p.motion_mm < 8.0 and 0.1 < p.motion_deg < 1.0 for p in suspects)
    message = result.sync.message()
    assert message.startswith("3 of 14 pairs look unsynchronised") and "p6" in message and "synchronised" in message
    _assert_truth(result, head)  # the outlier rule kept them out of the fit


def _ros_matrix(text: str, key: str) -> np.ndarray:
    m = re.search(rf"{key}:\n  rows: (\d+)\n  cols: (\d+)\n  data: \[(.*)\]", text)
    return np.array([float(v) for v in m.group(3).split(",")]).reshape(int(m.group(1)), int(m.group(2)))


@pytest.mark.slow
def test_exports_of_a_fisheye_head_load_in_opencv_ros_and_kalibr(tmp_path: Path) -> None:
    head, _ = _views("equidistant 150deg chessboard 9x6")
    result = _result("equidistant 150deg chessboard 9x6")
    write_outputs(result, tmp_path)
    fs = cv2.FileStorage(str(tmp_path / "calibration.yaml"), cv2.FILE_STORAGE_READ)
    assert fs.getNode("lens_model").string() == "equidistant"
    K1, D1 = fs.getNode("K1").mat(), fs.getNode("D1").mat()
    fs.release()
    ray = np.array([[[0.9, -0.4]]])  # ~44 degrees off axis: through the truth, back through the file
    pix = cv2.fisheye.distortPoints(ray, head.left.K, head.left.D)
    np.testing.assert_allclose(cv2.fisheye.undistortPoints(pix, K1, D1.ravel()), ray, atol=2e-3)
    left = (tmp_path / "left.yaml").read_text()
    assert "distortion_model: equidistant" in left and _ros_matrix(left, "distortion_coefficients").size == 4
    chain = yaml.safe_load((tmp_path / "camchain.yaml").read_text())
    assert chain["cam0"]["distortion_model"] == chain["cam1"]["distortion_model"] == "equidistant"
    T = np.array(chain["cam1"]["T_cn_cnm1"])
    np.testing.assert_allclose(T[:3, :3], result.calibration.R, atol=1e-12)
    np.testing.assert_allclose(T[:3, 3], result.calibration.T.ravel(), atol=1e-12)
    np.testing.assert_allclose(chain["cam0"]["intrinsics"], [K1[0, 0], K1[1, 1], K1[0, 2], K1[1, 2]])
    assert chain["cam1"]["resolution"] == list(SIZE)


@pytest.mark.slow
def test_a_rational_head_exports_ros_rational_polynomial_and_no_camchain(tmp_path: Path) -> None:
    result = _result("rational 130deg chessboard 9x6")
    write_outputs(result, tmp_path)
    right = (tmp_path / "right.yaml").read_text()
    assert "distortion_model: rational_polynomial" in right
    np.testing.assert_allclose(_ros_matrix(right, "distortion_coefficients").ravel(), result.calibration.D_right)
    assert not (tmp_path / "camchain.yaml").exists()  # Kalibr has no rational model


@pytest.mark.slow
def test_free_running_cameras_are_told_their_pairs_are_not_simultaneous(tmp_path: Path, capsys) -> None:
    """Every pair's right frame a moment late (webcams without sync): the gate fails, and the user
    reads why, with the evidence, on stdout and in calibration.json."""
    from stereocam.tools import cli
    from stereocam.tools.calibration import calibrate

    head = synth.rig("plumb_bob", 70, SIZE)
    pairs = synth.stereo_views(head, synth.chessboard(9, 6, 0.03), 14, seed=3, distance=(0.2, 0.5),
                               free_running=True)
    for i, (left, right) in enumerate(pairs):
        cv2.imwrite(str(tmp_path / f"left_{i:02d}.png"), left)
        cv2.imwrite(str(tmp_path / f"right_{i:02d}.png"), right)
    out = tmp_path / "out"
    code = cli.main(["calibrate", "-q", "--images", str(tmp_path), "--board", "9x6", "--square-size", "0.03",
                     "--out", str(out), "--db", str(tmp_path / "f.sqlite")])
    assert code == calibrate.EXIT_GATE
    text = capsys.readouterr().out
    assert "14 of 14 pairs look unsynchronised" in text and "left_07.png" in text and "synchronised" in text
    doc = yaml.safe_load((out / "calibration.json").read_text())
    assert len(doc["unsynchronised_pairs"]) == 14
    motion = [p["board_motion_mm"] for p in doc["unsynchronised_pairs"]]  # 3.5 mm shift + 0.4 deg turn
    assert 2.0 < np.median(motion) < 6.0 and max(motion) < 10.0
