"""Bad input to ``stereocam calibrate`` / ``stereocam factory``: a clear one-line message and exit 2,
never a traceback, and a refused command creates neither the output folder nor the database."""
from __future__ import annotations

import math
import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from stereocam.protocol.errors import ConfigError
from stereocam.tools import cli
from stereocam.tools.calibration.board_text import parse_board
from stereocam.tools.calibration.boards import detect_all
from stereocam.tools.calibration.fit import OutlierRules, choose_model
from stereocam.tools.calibration.solve import SolveConfig
from stereocam.tools.exit_codes import EXIT_USAGE
from stereocam.tools.factory.db import FactoryDB, FactoryDBError


def _images(folder: Path, size: tuple[int, int] = (64, 48), pairs: int = 2) -> Path:
    folder.mkdir()
    blank = np.full((size[1], size[0]), 128, np.uint8)
    for i in range(pairs):
        cv2.imwrite(str(folder / f"left{i:02d}.png"), blank)
        cv2.imwrite(str(folder / f"right{i:02d}.png"), blank)
    return folder


def _calibrate(tmp_path: Path, *extra: str, images: Path | None = None) -> int:
    images = images or _images(tmp_path / "im")
    return cli.main(["calibrate", "-q", "--images", str(images), "--out", str(tmp_path / "out"),
                     "--db", str(tmp_path / "f.sqlite"), *extra])


def _refused(capsys: pytest.CaptureFixture[str], tmp_path: Path, rc: int, *words: str) -> str:
    """Exit 2, one line naming ``words``, nothing made."""
    err = capsys.readouterr().err
    assert rc == EXIT_USAGE, err
    assert "Traceback" not in err and all(w in err for w in words), err
    assert not (tmp_path / "out").exists() and not (tmp_path / "f.sqlite").exists()
    return err


def test_images_too_small_for_the_board_are_dropped_with_the_reason(tmp_path: Path, capsys) -> None:
    rc = _calibrate(tmp_path, "--square-size", "0.03", images=_images(tmp_path / "tiny", (2, 2), 6))
    err = capsys.readouterr().err
    assert rc == EXIT_USAGE and "Traceback" not in err, err
    assert "none of the 6 pairs could be used" in err and "2x2 px is too small to hold the 9x6" in err
    assert not (tmp_path / "out").exists()
    tiny = np.zeros((14, 14), np.uint8)  # cv2.findChessboardCorners asserts on it; every detector is spared it
    for text in ("9x6", "charuco:5x7:0.04:0.03:DICT_4X4_50", "aprilgrid:6x6:0.088:0.3"):
        assert detect_all(tiny, parse_board(text, 0.03 if text == "9x6" else None)) == {}


@pytest.mark.parametrize("board, words", [
    ("charuco:5x7:0:0.01:DICT_4X4_50", "board SQUARE must be a finite number > 0, got '0'"),
    ("charuco:5x7:0.04:1e999:DICT_4X4_50", "board MARKER must be a finite number > 0"),
    ("charuco:500x500:0.04:0.03:DICT_4X4_50", "board COLS must be 3..100, got 500"),
    ("charuco:20x20:0.04:0.03:DICT_4X4_50", "a 20x20 ChArUco board needs 200 markers; DICT_4X4_50 has 50"),
    ("aprilgrid:6x6:-0.088:0.3", "board TAG_SIZE must be a finite number > 0, got '-0.088'"),
    ("1x6", "board COLS must be 2..100, got 1"),
])
def test_board_numbers_are_checked(tmp_path: Path, capsys, board: str, words: str) -> None:
    _refused(capsys, tmp_path, _calibrate(tmp_path, "--board", board, "--square-size", "0.03"), words)


@pytest.mark.parametrize("fields, words", [
    ("target_type: aprilgrid\ntagCols: [1]\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\n",
     "tagCols must be a whole number 1..100, got [1]"),
    ("target_type: aprilgrid\ntagCols: .inf\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\n",
     "tagCols must be a whole number 1..100, got inf"),
    ("target_type: checkerboard\ntargetCols: ~\ntargetRows: 6\nrowSpacingMeters: 0.03\ncolSpacingMeters: 0.03\n",
     "targetCols must be a whole number 1..100, got None"),
    ("target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\nrowSpacingMeters: {a: 1}\ncolSpacingMeters: 0.03\n",
     "rowSpacingMeters must be a finite number > 0, got {'a': 1}"),
])
def test_kalibr_target_fields_of_the_wrong_type_are_named(tmp_path: Path, capsys, fields: str, words: str) -> None:
    target = tmp_path / "target.yaml"
    target.write_text(fields)
    _refused(capsys, tmp_path, _calibrate(tmp_path, "--board", str(target)), f"{target}: {words}")


@pytest.mark.parametrize("option, value, words", [
    ("--model-tie", "-1", "-1.0 is not in the range x>=0"),
    ("--model-tie", "nan", "'nan' is not a finite number"),
    ("--outlier-rounds", "-1", "-1 is not in the range x>=0"),
])
def test_model_and_outlier_rules_are_checked(tmp_path: Path, capsys, option: str, value: str, words: str) -> None:
    _refused(capsys, tmp_path, _calibrate(tmp_path, "--square-size", "0.03", option, value), option, words)
    with pytest.raises(ConfigError, match="outlier rounds must be a whole number >= 0"):
        OutlierRules(rounds=-1)
    with pytest.raises(ConfigError, match="model tie must be a finite number >= 0"):
        choose_model(["plumb_bob"], [], [], (640, 480), math.nan)  # refused before any fit


@pytest.mark.parametrize("option, value, words", [
    ("--max-stereo-rms", "nan", "'nan' is not a finite number"),
    ("--max-epipolar", "nan", "'nan' is not a finite number"),
    ("--max-epipolar", "inf", "'inf' is not a finite number"),
    ("--max-pixel-aspect", "nan", "'nan' is not a finite number"),
    ("--baseline-range", "0.01:inf", "MIN and MAX must be finite numbers"),
    ("--max-drop-fraction", "nan", "'nan' is not a finite number"),
    ("--max-drop-fraction", "1.5", "1.5 is not in the range 0<=x<=1"),
    ("--outlier-k", "-1", "-1.0 is not in the range x>=0"),
    ("--max-views", "0", "0 is not in the range x>=1"),
])
def test_gates_and_limits_must_be_finite_and_in_range(tmp_path: Path, capsys, option: str, value: str,
                                                       words: str) -> None:
    _refused(capsys, tmp_path, _calibrate(tmp_path, "--square-size", "0.03", option, value), option, words)
    with pytest.raises(ConfigError, match="gate max_epipolar_rms_px must be a number, got NaN"):
        SolveConfig(max_epipolar_rms_px=math.nan)
    with pytest.raises(ConfigError, match="outlier max_drop_fraction must be a finite number within 0..1"):
        OutlierRules(max_drop_fraction=math.nan)


def test_an_empty_db_is_a_usage_error_not_the_default_database(tmp_path: Path, capsys) -> None:
    default = Path(os.environ["STEREOCAM_FACTORY_DB"])
    existed = default.exists()
    images = _images(tmp_path / "im")
    for argv in (["calibrate", "-q", "--images", str(images), "--square-size", "0.03", "--out", str(tmp_path / "out"),
                  "--db", ""],
                 ["factory", "report", "--db", ""]):
        assert cli.main(argv) == EXIT_USAGE
        err = capsys.readouterr().err
        assert "Invalid value for '--db': must name a database" in err and "Traceback" not in err, err
    assert default.exists() == existed and not (tmp_path / "out").exists()
    with pytest.raises(FactoryDBError, match="an empty URL"):
        FactoryDB("")
