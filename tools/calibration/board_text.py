"""The ``--board`` text and Kalibr target yamls, as the board specs of boards.py.

Board syntax (``--board``):
  COLSxROWS                               chessboard, inner corners (square side from --square-size);
                                          square boards (N x N) too
  charuco:COLSxROWS:SQUARE:MARKER:DICT    ChArUco, squares (not corners), SQUARE and MARKER in metres,
                                          DICT an OpenCV dictionary name, e.g. DICT_4X4_250; a
                                          --square-size given with it rescales both lengths
  aprilgrid:COLSxROWS:TAG_SIZE:SPACING    Kalibr's AprilGrid: COLS x ROWS tags of tag36h11 (2-bit black
                                          border), TAG_SIZE in metres, SPACING the gap / TAG_SIZE
  FILE.yaml                               a Kalibr target yaml (target_type aprilgrid or checkerboard)

Every count and length is checked (ValueError naming it): sides up to boards.MAX_BOARD_SIDE, lengths
finite and > 0, a ChArUco board no bigger than its dictionary (CharucoSpec).
"""
from __future__ import annotations

import math
import re
from pathlib import Path

from stereocam.stereo.calibration_board import BoardSpec
from stereocam.tools.calibration.boards import MAX_BOARD_SIDE, AprilGridSpec, Board, CharucoSpec, positive


def parse_board(text: str, square_size: float | None) -> Board:
    """Parse the --board syntax of the module docstring; raises ValueError (a length that is not a
    finite number > 0, over MAX_BOARD_SIDE a side, a ChArUco board its dictionary is too small for)."""
    if square_size is not None:
        positive(square_size, "--square-size")
    m = re.fullmatch(r"(\d+)[xX](\d+)", text)
    if m:
        if square_size is None:
            raise ValueError("--square-size is required with a chessboard")
        return BoardSpec(_side(m.group(1), "COLS", 2), _side(m.group(2), "ROWS", 2), square_size)
    m = re.fullmatch(r"charuco:(\d+)[xX](\d+):([0-9.eE+-]+):([0-9.eE+-]+):(\w+)", text, re.IGNORECASE)
    if m:
        square, marker = _number(m.group(3), "SQUARE"), _number(m.group(4), "MARKER")
        if square_size is not None and square_size != square:  # --square-size rescales the board
            marker, square = marker * square_size / square, square_size
        return CharucoSpec(_side(m.group(1), "COLS", 3), _side(m.group(2), "ROWS", 3), square, marker, m.group(5).upper())
    m = re.fullmatch(r"aprilgrid:(\d+)[xX](\d+):([0-9.eE+-]+):([0-9.eE+-]+)", text, re.IGNORECASE)
    if m:
        return AprilGridSpec(_side(m.group(1), "COLS", 1), _side(m.group(2), "ROWS", 1), _number(m.group(3), "TAG_SIZE"),
                             _number(m.group(4), "SPACING"))
    if text.lower().endswith((".yaml", ".yml")):
        return read_kalibr_target(Path(text))
    raise ValueError(f"board must be COLSxROWS inner corners (e.g. 9x6), charuco:COLSxROWS:SQUARE:MARKER:DICT, "
                     f"aprilgrid:COLSxROWS:TAG_SIZE:SPACING or a Kalibr target .yaml, got {text!r}")


def read_kalibr_target(path: Path) -> Board:
    """The board of a Kalibr target yaml (aprilgrid: tagCols, tagRows, tagSize, tagSpacing;
    checkerboard: targetCols, targetRows inner corners, rowSpacingMeters, colSpacingMeters)."""
    import yaml

    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise ValueError(f"cannot read the target yaml {path}: {exc}") from exc
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: not a Kalibr target yaml")
    kind = str(doc.get("target_type", "")).strip("'\"")
    if kind not in ("aprilgrid", "checkerboard"):
        raise ValueError(f"{path}: target_type {kind!r} is not supported (aprilgrid or checkerboard)")
    try:
        if kind == "aprilgrid":
            return AprilGridSpec(_yaml_count(doc, "tagCols"), _yaml_count(doc, "tagRows"),
                                 _yaml_number(doc, "tagSize"), _yaml_number(doc, "tagSpacing"))
        row, col = _yaml_number(doc, "rowSpacingMeters"), _yaml_number(doc, "colSpacingMeters")
        if abs(row - col) > 1e-9 * max(row, col):
            raise ValueError(f"only square checkerboard cells are supported ({col} x {row} m)")
        return BoardSpec(_yaml_count(doc, "targetCols"), _yaml_count(doc, "targetRows"), col)
    except KeyError as exc:
        raise ValueError(f"{path}: {kind} target without {exc.args[0]}") from None
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from exc


def _yaml_number(doc: dict, key: str) -> float:
    """A length or ratio field of a Kalibr target yaml: a finite number > 0 (KeyError where missing)."""
    value = doc[key]
    try:
        number = float(value) if isinstance(value, (int, float, str)) and not isinstance(value, bool) else math.nan
    except (ValueError, OverflowError):
        number = math.nan
    if not (math.isfinite(number) and number > 0):
        raise ValueError(f"{key} must be a finite number > 0, got {value!r}")
    return number


def _yaml_count(doc: dict, key: str) -> int:
    """A count field of a Kalibr target yaml: a whole number 1..MAX_BOARD_SIDE (KeyError where missing)."""
    value = doc[key]
    try:
        number = _yaml_number(doc, key)
    except ValueError:
        number = math.nan
    if not (number.is_integer() and 1 <= number <= MAX_BOARD_SIDE):
        raise ValueError(f"{key} must be a whole number 1..{MAX_BOARD_SIDE}, got {value!r}")
    return int(number)


def _side(text: str, what: str, low: int) -> int:
    """A board's count along a side from the --board text, low..MAX_BOARD_SIDE; else ValueError."""
    if len(text.lstrip("0")) > 3 or not low <= int(text) <= MAX_BOARD_SIDE:
        raise ValueError(f"board {what} must be {low}..{MAX_BOARD_SIDE}, got {text}")
    return int(text)


def _number(text: str, what: str) -> float:
    """A length or ratio of the --board text: a finite number > 0; else ValueError naming ``what``."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"board {what} must be a finite number > 0, got {text!r}")
    return value
