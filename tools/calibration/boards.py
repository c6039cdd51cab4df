"""Calibration targets for the tool: plain chessboards and ChArUco boards, their detection in one
image and the matching of a left/right pair into common object/image points.

Board syntax (``--board``):
  COLSxROWS                               chessboard, inner corners (square side from --square-size)
  charuco:COLSxROWS:SQUARE:MARKER:DICT    ChArUco, squares (not corners), SQUARE and MARKER in metres,
                                          DICT an OpenCV dictionary name, e.g. DICT_4X4_250; a
                                          --square-size given with it rescales both lengths

Chessboards are looked for with both OpenCV detectors: cv2.findChessboardCorners (adaptive
threshold, normalised; then cv2.cornerSubPix with a half-window of 0.4 × the smallest corner
spacing, 2..15 px) and, where that finds nothing (no white margin, strong distortion, dot-coded
squares), the sector-based cv2.findChessboardCornersSB (plain, then exhaustive). Both run on
every image; the solver uses, for the whole set, the detector whose corners fit a camera model
best (tools/calibration/solve.py), and the other one for the images only it finds. A grid whose two sizes are both odd or both
even looks the same turned by 180 degrees, so the detectors may number it from either end: the
right view's order is reversed when its first→last corner direction opposes the left view's.

ChArUco boards: cv2.aruco.CharucoDetector; each corner has its board id, so partial views are
fine and a pair keeps the ids seen in both images. The board's layout (OpenCV >= 4.6, or the
legacy one of older OpenCV that boards with an even number of rows were printed with) is settled
by the first image with the board in it: whichever layout finds more corners there.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

import cv2
import numpy as np

from stereocam.stereo.calibration_board import BoardSpec

_SUBPIX = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
MIN_CHARUCO_CORNERS = 8


@dataclass(frozen=True)
class Detection:
    """Board corners seen in one image: board ids, image points (N, 2) and object points (N, 3)."""

    ids: np.ndarray
    image_points: np.ndarray
    object_points: np.ndarray


@dataclass
class CharucoSpec:
    """ChArUco board: cols x rows squares, square and marker side (metres), dictionary name."""

    cols: int
    rows: int
    square_m: float
    marker_m: float
    dictionary: str
    legacy: bool | None = None  # None: decided on the first images
    _detectors: dict = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        if self.cols < 3 or self.rows < 3 or not 0 < self.marker_m < self.square_m:
            raise ValueError(f"bad ChArUco board {self.cols}x{self.rows} square {self.square_m} marker {self.marker_m}")
        if not self.dictionary.startswith("DICT_") or not hasattr(cv2.aruco, self.dictionary):
            raise ValueError(f"unknown ArUco dictionary {self.dictionary!r} (e.g. DICT_4X4_250)")

    def describe(self) -> str:
        return f"charuco:{self.cols}x{self.rows}:{self.square_m:g}:{self.marker_m:g}:{self.dictionary}"

    def _detector(self, legacy: bool) -> "cv2.aruco.CharucoDetector":
        if legacy not in self._detectors:
            d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
            board = cv2.aruco.CharucoBoard((self.cols, self.rows), self.square_m, self.marker_m, d)
            board.setLegacyPattern(legacy)
            self._detectors[legacy] = cv2.aruco.CharucoDetector(board)
        return self._detectors[legacy]

    def detect_with(self, gray: np.ndarray, legacy: bool) -> Detection | None:
        det = self._detector(legacy)
        corners, ids, *_ = det.detectBoard(gray)
        if ids is None or len(ids) < MIN_CHARUCO_CORNERS:
            return None
        ids = ids.ravel().astype(np.int64)
        obj = np.asarray(det.getBoard().getChessboardCorners(), np.float32)[ids]
        return Detection(ids, corners.reshape(-1, 2).astype(np.float32), obj)


def describe(board: BoardSpec | CharucoSpec) -> str:
    """The --board text of a board (for records and reports)."""
    if isinstance(board, CharucoSpec):
        return board.describe()
    return f"{board.cols}x{board.rows}:{board.square_m:g}"


def parse_board(text: str, square_size: float | None) -> BoardSpec | CharucoSpec:
    """Parse the --board syntax of the module docstring; raises ValueError."""
    m = re.fullmatch(r"(\d+)[xX](\d+)", text)
    if m:
        if square_size is None:
            raise ValueError("--square-size is required with a chessboard")
        cols, rows = int(m.group(1)), int(m.group(2))
        if cols == rows:
            raise ValueError("use a board with cols != rows so its orientation is unambiguous")
        return BoardSpec(cols, rows, square_size)
    m = re.fullmatch(r"charuco:(\d+)[xX](\d+):([0-9.eE+-]+):([0-9.eE+-]+):(\w+)", text, re.IGNORECASE)
    if m:
        square, marker = float(m.group(3)), float(m.group(4))
        if square_size is not None and square_size != square:  # --square-size rescales the board
            marker, square = marker * square_size / square, square_size
        return CharucoSpec(int(m.group(1)), int(m.group(2)), square, marker, m.group(5).upper())
    raise ValueError(f"board must be COLSxROWS inner corners (e.g. 9x6) or "
                     f"charuco:COLSxROWS:SQUARE:MARKER:DICT, got {text!r}")


def gray(img: np.ndarray) -> np.ndarray:
    """The image as 2-D uint8 (BGR is converted)."""
    if img.dtype != np.uint8:
        raise ValueError(f"images must be uint8, got {img.dtype}")
    if img.ndim == 3:
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    if img.ndim != 2:
        raise ValueError(f"images must be HxW or HxWx3, got shape {img.shape}")
    return img


def _classic(g: np.ndarray, board: BoardSpec) -> np.ndarray | None:
    size = (board.cols, board.rows)
    found, corners = cv2.findChessboardCorners(g, size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not found:
        return None
    grid = corners.reshape(board.rows, board.cols, 2)
    spacing = min(np.linalg.norm(np.diff(grid, axis=0), axis=2).min(),
                  np.linalg.norm(np.diff(grid, axis=1), axis=2).min())
    half = int(np.clip(0.4 * spacing, 2, 15))
    return cv2.cornerSubPix(g, corners, (half, half), (-1, -1), _SUBPIX).reshape(-1, 2)


def _sector_based(g: np.ndarray, board: BoardSpec) -> np.ndarray | None:
    for flags in (0, cv2.CALIB_CB_EXHAUSTIVE):  # normalising the image costs accuracy here
        found, corners = cv2.findChessboardCornersSB(g, (board.cols, board.rows), flags=flags)
        if found:
            return corners.reshape(-1, 2)
    return None


CHESSBOARD_DETECTORS = {"classic": _classic, "sector": _sector_based}


def detect_all(img: np.ndarray, board: BoardSpec | CharucoSpec) -> dict[str, Detection]:
    """The board's corners in one image by each detector that finds it ({} when none does)."""
    g = gray(img)
    if isinstance(board, CharucoSpec):
        found = detect_charuco(g, board)
        return {} if found is None else {"charuco": found}
    out = {}
    for name, detector in CHESSBOARD_DETECTORS.items():
        corners = detector(g, board)
        if corners is not None:
            out[name] = Detection(np.arange(board.cols * board.rows), corners.astype(np.float32),
                                  board.object_points())
    return out


def detect_charuco(g: np.ndarray, board: CharucoSpec) -> Detection | None:
    """ChArUco corners of one grey image; the first image with the board settles the layout."""
    if board.legacy is not None:
        return board.detect_with(g, board.legacy)
    found = {legacy: board.detect_with(g, legacy) for legacy in (False, True)}
    counts = {legacy: 0 if d is None else len(d.ids) for legacy, d in found.items()}
    if max(counts.values()) > 0:
        board.legacy = counts[True] > counts[False]
        return found[board.legacy]
    return None


def match_pair(left: Detection, right: Detection, board: BoardSpec | CharucoSpec
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(object points, left points, right points) of the corners seen in both images, or None."""
    if isinstance(board, BoardSpec):
        r = right.image_points
        if np.dot(left.image_points[-1] - left.image_points[0], r[-1] - r[0]) < 0:
            r = r[::-1].copy()
        return left.object_points, left.image_points, r
    common, li, ri = np.intersect1d(left.ids, right.ids, return_indices=True)
    if len(common) < MIN_CHARUCO_CORNERS:
        return None
    return left.object_points[li], left.image_points[li], right.image_points[ri]
