"""Calibration targets for the tool: plain chessboards and ChArUco boards, their detection in one
image and the matching of a left/right pair into common object/image points.

The ``--board`` text and Kalibr target yamls become these specs in board_text.py.

Chessboards are looked for with both OpenCV detectors: cv2.findChessboardCorners (adaptive
threshold, normalised; then cv2.cornerSubPix with a half-window of 0.4 × the smallest corner
spacing, 2..15 px) and, where that finds nothing (no white margin, strong distortion, dot-coded
squares), the sector-based cv2.findChessboardCornersSB (plain, then exhaustive). The sector-based
corners are also offered refined by cv2.cornerSubPix, as a third candidate ("sector_subpix"; an
image where a corner could not be placed has none): unrefined, the sector-based corners of a 120°
lens at 640x480 are 0.3-4 px off, refined within 0.25 px; but on dot-coded squares (ECoCheck) the
dots pull the refinement off. All run on every image; the solver uses, for the whole set, the
candidate whose corners fit a camera model best (tools/calibration/solve.py), and another one for
the images only it finds. A chessboard looks
the same turned by 180 degrees (a square one also turned by 90 degrees or mirrored), so the
detectors may number it from any of those ends. Only the left/right agreement matters (each pair
has its own board pose, and a plane's points numbered mirrored are still a plane seen from the
other side): the right view is renumbered by the grid symmetry whose row and column directions
agree best with the left view's, the relative rotation of a stereo head being far below 45 degrees.

ChArUco boards: cv2.aruco.CharucoDetector; each corner has its board id, so partial views are
fine and a pair keeps the ids seen in both images. Its corners are also offered refined inside the
markers' white margin ("charuco_subpix", refine_charuco), chosen per set as the sector-based ones are. The board's layout (OpenCV >= 4.6, or the
legacy one of older OpenCV that boards with an even number of rows were printed with) and its
polarity (black markers on white, or printed inverted: white on black) are settled by the first
image with the board in it: whichever of the four finds more corners there.

AprilGrid (Kalibr): cv2.aruco's DICT_APRILTAG_36h11 (the apriltag library's tag36h11 codes) with a
2-bit marker border, corners refined to sub-pixel (AprilGridSpec.detect). Tag id = row·COLS + col, row 0 at the bottom of
the printed board; the tag corners are Kalibr's points: a (2·ROWS) x (2·COLS) grid, point
(2·row + top, 2·col + right) at ((col·(1+SPACING) + right)·TAG_SIZE, (row·(1+SPACING) + top)·TAG_SIZE).
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field

import cv2
import numpy as np

from stereocam.stereo.calibration_board import BoardSpec
from stereocam.tools.calibration import detection_cache

_SUBPIX = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
MIN_CHARUCO_CORNERS = 8
MIN_TAG_PX = 16  # AprilGrid tags seen smaller (side, px) give no sub-pixel corners
MAX_BOARD_SIDE = 100  # squares (ChArUco), inner corners (chessboard) or tags (AprilGrid) along a side
MIN_IMAGE_PX = 16  # an image side under this holds no board (cv2.findChessboardCorners asserts under 15)
MIN_SQUARE_PX = 2  # a chessboard, wholly in view, needs at least this many px a square


def positive(value: float, what: str) -> float:
    """``value`` if it is a finite number > 0; else ValueError naming ``what``."""
    if isinstance(value, bool) or not (isinstance(value, numbers.Real) and math.isfinite(value) and value > 0):
        raise ValueError(f"{what} must be a finite number > 0, got {value!r}")
    return float(value)


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
    inverted: bool | None = None  # white markers on black; None: decided on the first images
    _detectors: dict = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        positive(self.square_m, "ChArUco square size")
        positive(self.marker_m, "ChArUco marker size")
        if not 3 <= self.cols <= MAX_BOARD_SIDE or not 3 <= self.rows <= MAX_BOARD_SIDE \
                or not self.marker_m < self.square_m:
            raise ValueError(f"bad ChArUco board {self.cols}x{self.rows} square {self.square_m} marker {self.marker_m} "
                             f"(3..{MAX_BOARD_SIDE} squares a side, the marker smaller than the square)")
        if not self.dictionary.startswith("DICT_") or not hasattr(cv2.aruco, self.dictionary):
            raise ValueError(f"unknown ArUco dictionary {self.dictionary!r} (e.g. DICT_4X4_250)")
        held = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary)).bytesList.shape[0]
        if self.cols * self.rows // 2 > held:
            raise ValueError(f"a {self.cols}x{self.rows} ChArUco board needs {self.cols * self.rows // 2} markers; "
                             f"{self.dictionary} has {held}")

    def describe(self) -> str:
        return f"charuco:{self.cols}x{self.rows}:{self.square_m:g}:{self.marker_m:g}:{self.dictionary}"

    def _detector(self, legacy: bool) -> "cv2.aruco.CharucoDetector":
        if legacy not in self._detectors:
            d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
            board = cv2.aruco.CharucoBoard((self.cols, self.rows), self.square_m, self.marker_m, d)
            board.setLegacyPattern(legacy)
            self._detectors[legacy] = cv2.aruco.CharucoDetector(board)
        return self._detectors[legacy]

    def detect_with(self, gray: np.ndarray, legacy: bool, inverted: bool = False) -> Detection | None:
        det = self._detector(legacy)
        corners, ids, *_ = det.detectBoard(255 - gray if inverted else gray)
        if ids is None or len(ids) < MIN_CHARUCO_CORNERS:
            return None
        ids = ids.ravel().astype(np.int64)
        obj = np.asarray(det.getBoard().getChessboardCorners(), np.float32)[ids]
        return Detection(ids, corners.reshape(-1, 2).astype(np.float32), obj)


@dataclass
class AprilGridSpec:
    """Kalibr's AprilGrid: cols x rows tag36h11 tags of tag_m metres, gaps of spacing·tag_m."""

    cols: int
    rows: int
    tag_m: float
    spacing: float
    _detector: "cv2.aruco.ArucoDetector | None" = field(default=None, repr=False)

    def __post_init__(self) -> None:
        positive(self.tag_m, "AprilGrid tag size")
        positive(self.spacing, "AprilGrid tag spacing")
        if self.cols < 1 or self.rows < 1 or self.cols * self.rows < 2 or not self.spacing < 5:
            raise ValueError(f"bad AprilGrid {self.cols}x{self.rows} tag {self.tag_m} spacing {self.spacing}")
        if self.cols * self.rows > 587:
            raise ValueError(f"an AprilGrid of tag36h11 has at most 587 tags, not {self.cols * self.rows}")

    def describe(self) -> str:
        return f"aprilgrid:{self.cols}x{self.rows}:{self.tag_m:g}:{self.spacing:g}"

    def object_points(self) -> np.ndarray:
        """Kalibr's points (see the module docstring), (4·cols·rows, 3), point id = index."""
        r2, c2 = np.mgrid[0:2 * self.rows, 0:2 * self.cols]
        x = ((c2 // 2) * (1 + self.spacing) + c2 % 2) * self.tag_m
        y = ((r2 // 2) * (1 + self.spacing) + r2 % 2) * self.tag_m
        return np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)]).astype(np.float32)

    def point_ids(self, tag_id: int) -> list[int]:
        """Point ids of a tag's corners in OpenCV's order (top-left, top-right, bottom-right,
        bottom-left of the printed tag; Kalibr's y points up the board)."""
        row, col = divmod(tag_id, self.cols)
        w = 2 * self.cols
        bottom, top = 2 * row * w, (2 * row + 1) * w
        return [top + 2 * col, top + 2 * col + 1, bottom + 2 * col + 1, bottom + 2 * col]

    def detect(self, gray: np.ndarray) -> Detection | None:
        """Tags found on the image and on it with the white grown by 1 and 2 px (which parts the tags
        from the black squares that touch their corners once the print is blurred); each tag corner
        is then refined on the image itself, where it is the saddle point of a tag and a square. A
        tag under MIN_TAG_PX, or one whose refinement jumps off its corner, is left out."""
        if self._detector is None:
            params = cv2.aruco.DetectorParameters()
            params.markerBorderBits = 2
            params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_CONTOUR  # edge lines, then the saddle
            dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
            self._detector = cv2.aruco.ArucoDetector(dictionary, params)
        quads: dict[int, tuple[np.ndarray, int]] = {}
        for grow in (0, 1, 2):
            img = gray if grow == 0 else cv2.dilate(gray, np.ones((2 * grow + 1, 2 * grow + 1), np.uint8))
            corners, ids, _ = self._detector.detectMarkers(img)
            for tag, quad in zip(() if ids is None else ids.ravel(), corners):
                if tag < self.cols * self.rows:
                    quads.setdefault(int(tag), (quad.reshape(4, 2), grow))
        point_ids, points = [], []
        for tag_id, (quad, grow) in sorted(quads.items()):
            side = float(np.mean(np.linalg.norm(quad - np.roll(quad, 1, axis=0), axis=1)))
            gap = self.spacing * side  # the black squares' side at this tag, px
            if side < MIN_TAG_PX:
                continue
            out = quad - quad.mean(axis=0)  # growing the white shrank the tag by `grow` px a side
            quad = quad + grow * np.sqrt(2) * out / np.linalg.norm(out, axis=1, keepdims=True)
            half = int(np.clip(0.4 * gap, 1, 12))
            refined = cv2.cornerSubPix(gray, quad.astype(np.float32).reshape(-1, 1, 2), (half, half), (-1, -1),
                                       _SUBPIX).reshape(4, 2)
            if np.max(np.linalg.norm(refined - quad, axis=1)) > 1.0 + 0.4 * gap:
                continue  # drawn to another saddle (the far corner of a small black square): not this corner
            point_ids += self.point_ids(tag_id)
            points.append(refined)
        if len(point_ids) < MIN_CHARUCO_CORNERS:
            return None
        ids_arr = np.array(point_ids, np.int64)
        return Detection(ids_arr, np.concatenate(points).astype(np.float32), self.object_points()[ids_arr])


Board = BoardSpec | CharucoSpec | AprilGridSpec


def describe(board: Board) -> str:
    """The --board text of a board (for records and reports)."""
    if isinstance(board, BoardSpec):
        return f"{board.cols}x{board.rows}:{board.square_m:g}"
    return board.describe()


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


def refine_sector(g: np.ndarray, corners: np.ndarray, board: BoardSpec) -> np.ndarray | None:
    """Sector-based corners refined by cv2.cornerSubPix (half-window 0.4 x the smallest corner
    spacing, 2..15 px); None when a corner could not be placed: cornerSubPix puts a corner that runs
    out of its window back where it started, exactly (seen at the squeezed outer corners of a
    wide-angle lens, where the detector's start is off by pixels)."""
    start = np.asarray(corners, np.float32).reshape(-1, 1, 2)
    grid = start.reshape(board.rows, board.cols, 2)
    spacing = min(np.linalg.norm(np.diff(grid, axis=0), axis=2).min(),
                  np.linalg.norm(np.diff(grid, axis=1), axis=2).min())
    half = int(np.clip(0.4 * spacing, 2, 15))
    refined = cv2.cornerSubPix(g, start.copy(), (half, half), (-1, -1), _SUBPIX).reshape(-1, 2)
    if np.any(np.all(refined == start.reshape(-1, 2), axis=1)):
        return None
    return refined


def refine_charuco(g: np.ndarray, found: Detection, board: CharucoSpec) -> Detection | None:
    """ChArUco corners refined by cv2.cornerSubPix in a window that stays inside the white margin
    around the markers: per corner a half-window of 0.65 x that margin ((1 - MARKER / SQUARE) / 2 of
    a square) x the distance to its nearest corner in the image, 2..15 px. On synthetic views through
    60-170 degree lenses, cv2.aruco.CharucoDetector's own corners are 0.07-0.14 px RMS off per view
    (worst corners 0.5-1.4 px: its window reaches the markers' edges); refined so, 0.06-0.07 (worst
    0.2-0.6). None when a corner could not be placed (cornerSubPix leaves it exactly where it was)."""
    pts = np.asarray(found.image_points, np.float32).reshape(-1, 2)
    if len(pts) < 2:
        return None
    d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    np.fill_diagonal(d, np.inf)
    margin = (1 - board.marker_m / board.square_m) / 2
    halves = np.clip(np.round(0.65 * margin * d.min(axis=1)), 2, 15).astype(int)
    refined = pts.copy()
    for half in np.unique(halves):
        sel = halves == half
        refined[sel] = cv2.cornerSubPix(g, pts[sel].reshape(-1, 1, 2).copy(), (int(half), int(half)), (-1, -1),
                                        _SUBPIX).reshape(-1, 2)
    if np.any(np.all(refined == pts, axis=1)):
        return None
    return Detection(found.ids, refined, found.object_points)


CHESSBOARD_DETECTORS = {"classic": _classic, "sector": _sector_based}
REFINED = {"sector": "sector_subpix", "charuco": "charuco_subpix"}
"""A detector's corners refined: a candidate of its own, which the solver takes for a set where they
fit better (solve.choose_detector)."""
SUBPIXEL_FIRST = ("classic", *REFINED.values())
"""Detections with sub-pixel refined corners: where a measurement takes its corners from first (the
rectified views' vertical disparity), not a solve (solve.py chooses per set)."""


def too_small(shape: tuple[int, ...], board: Board) -> str | None:
    """Why an image of ``shape`` (H, W, ...) cannot hold ``board``, or None: a side under MIN_IMAGE_PX,
    or (a chessboard, only found wholly in view) under MIN_SQUARE_PX px a square along a side."""
    h, w = shape[:2]
    need = [MIN_IMAGE_PX, MIN_IMAGE_PX]
    if isinstance(board, BoardSpec):
        need = [max(MIN_IMAGE_PX, MIN_SQUARE_PX * n) for n in sorted((board.cols + 1, board.rows + 1))]
    if min(w, h) < need[0] or max(w, h) < need[1]:
        return f"{w}x{h} px is too small to hold the {describe(board)} board (at least {need[1]}x{need[0]} px)"
    return None


def detect_all(img: np.ndarray, board: Board) -> dict[str, Detection]:
    """The board's corners in one image by each detector that finds it ({} when none does, or when
    the image is too small to hold the board: too_small)."""
    g = gray(img)
    if too_small(g.shape, board) is not None:  # OpenCV's detectors assert on such images
        return {}
    if isinstance(board, CharucoSpec):
        found = detect_charuco(g, board)
        if found is None:
            return {}
        subpix = refine_charuco(g, found, board)
        return {"charuco": found} if subpix is None else {"charuco": found, "charuco_subpix": subpix}
    cache = detection_cache.entry(g, repr(board))  # ChArUco is not cached: it settles the layout
    hit = detection_cache.load(cache)
    if hit is not None:
        return {name: Detection(*arrays) for name, arrays in hit.items()}
    out = {}
    if isinstance(board, AprilGridSpec):
        found = board.detect(g)
        if found is not None:
            out["aprilgrid"] = found
    else:
        for name, detector in CHESSBOARD_DETECTORS.items():
            corners = detector(g, board)
            refined = None if corners is None or name not in REFINED else refine_sector(g, corners, board)
            for key, points in ((name, corners), (REFINED.get(name), refined)):
                if key is not None and points is not None:
                    out[key] = Detection(np.arange(board.cols * board.rows), points.astype(np.float32),
                                         board.object_points())
    detection_cache.store(cache, {name: (d.ids, d.image_points, d.object_points) for name, d in out.items()})
    return out


def detect_charuco(g: np.ndarray, board: CharucoSpec) -> Detection | None:
    """ChArUco corners of one grey image; the first image with the board settles layout and polarity."""
    if board.legacy is not None and board.inverted is not None:
        return board.detect_with(g, board.legacy, board.inverted)
    found = {(legacy, inv): board.detect_with(g, legacy, inv) for inv in (False, True) for legacy in (False, True)}
    counts = {key: 0 if d is None else len(d.ids) for key, d in found.items()}
    best = max(counts, key=lambda key: counts[key])  # ties: the current layout, normal polarity
    if counts[best] > 0:
        board.legacy, board.inverted = best
        return found[best]
    return None


def grid_orders(cols: int, rows: int) -> list[np.ndarray]:
    """Index arrays renumbering a cols x rows grid by each symmetry that maps it onto itself."""
    grid = np.arange(cols * rows).reshape(rows, cols)
    out = [grid, grid[::-1, ::-1], grid[::-1], grid[:, ::-1]]
    if cols == rows:
        out += [np.rot90(grid, 1), np.rot90(grid, 3), grid.T, grid.T[::-1, ::-1]]
    return [o.ravel() for o in out]


def _axes(points: np.ndarray, cols: int, rows: int) -> np.ndarray:
    """Mean unit direction along the rows and along the columns of a detected grid, (2, 2)."""
    g = points.reshape(rows, cols, 2).astype(np.float64)
    along = [np.diff(g, axis=1).reshape(-1, 2).sum(0), np.diff(g, axis=0).reshape(-1, 2).sum(0)]
    return np.array([a / max(np.linalg.norm(a), 1e-12) for a in along])


def match_pair(left: Detection, right: Detection, board: Board
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(object points, left points, right points) of the corners seen in both images, or None."""
    if isinstance(board, BoardSpec):
        axes = _axes(left.image_points, board.cols, board.rows)
        r = max((right.image_points[o] for o in grid_orders(board.cols, board.rows)),
                key=lambda pts: float(np.sum(axes * _axes(pts, board.cols, board.rows))))
        return left.object_points, left.image_points, r.copy()
    common, li, ri = np.intersect1d(left.ids, right.ids, return_indices=True)
    if len(common) < MIN_CHARUCO_CORNERS:
        return None
    return left.object_points[li], left.image_points[li], right.image_points[ri]
