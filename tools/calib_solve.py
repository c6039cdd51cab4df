"""Factory stereo calibration engine: detect, select views, solve, measure, gate.

calibrate_pairs() consumes an iterator of raw (left, right) u8 image pairs — files in offline mode,
the device's raw stream in device mode — and returns a CalibrationResult. It stops reading once
`max_views` views are kept and `min_holdout` pairs are held out, so an endless stream is fine.

Pipeline and exact metric definitions (units: pixels of the raw image, N = number of corners):
  1. Detect: cv2.findChessboardCorners (adaptive threshold, normalise) then cv2.cornerSubPix with
     a half-window of 0.4 × the smallest corner spacing (2..15 px). A pair counts only when the
     board is found in both images; the right corner order is reversed if it runs opposite to the
     left one.
  2. Hold out: of the pairs with both boards, every `holdout_every`-th one (the 5th, 10th, ...)
     is never used in the solve; it is only used for the epipolar metric.
  3. Select (ROS camera_calibration style): the left view gives p = (X, Y, size, skew) in [0,1]^4:
     X, Y = mean corner position, the image shrunk by half the board's apparent size; size =
     sqrt(board quad area / image area); skew = min(1, 2·|π/2 − angle at the top-right corner|).
     A view is kept only if its L1 distance to every kept view is > min_distance (0.2);
     coverage per parameter = min(1, (max − min) / range), ranges (0.7, 0.7, 0.4, 0.5).
  4. Solve: cv2.calibrateCamera per camera (5 coefficients), cv2.stereoCalibrate with
     CALIB_FIX_INTRINSIC, cv2.stereoRectify with CALIB_ZERO_DISPARITY and alpha = 0.
  5. Metrics:
       rms_left / rms_right = sqrt( Σ_views Σ_corners |x_obs − x_proj|² / N ) of that camera's
         own calibrateCamera solve (the value cv2.calibrateCamera returns), |·| the 2-D distance;
       rms_stereo = sqrt( Σ_views Σ_corners (|l_obs − l_proj|² + |r_obs − r_proj|²) / (2N) ) with
         one board pose per view and the right pose derived through (R, T) — the value
         cv2.stereoCalibrate returns;
       epipolar_rms_px = sqrt( Σ_held-out Σ_corners (y_left_rect − y_right_rect)² / N ) where
         *_rect are the corners mapped through undistortion + rectification (R1/P1, R2/P2), on
         held-out pairs only.
  6. Gate (CalibrationResult.failures lists every failed rule; passed = none failed):
       rms_stereo ≤ max_stereo_rms_px (0.5); epipolar_rms_px ≤ max_epipolar_rms_px (0.3);
       plausibility: both principal points inside the image, |fx/fy − 1| ≤ 5 % for both cameras.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Literal

import cv2
import numpy as np

from stereocam.device_sim.calibration.board import BoardSpec
from stereocam.protocol.calibration import CalibrationQuality, StereoCalibration
from stereocam.protocol.errors import StereoCamError

PARAM_NAMES = ("X", "Y", "Size", "Skew")
PARAM_RANGES = (0.7, 0.7, 0.4, 0.5)
_SUBPIX = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
_SOLVE = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-12)
_UNDIST = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-12)

ViewStatus = Literal["used", "held_out", "redundant", "no_board"]


class CalibrationError(StereoCamError):
    """Calibration could not produce a solution at all."""


class BoardNotFoundError(CalibrationError):
    """No pair showed the board in both images."""


class TooFewViewsError(CalibrationError):
    """Not enough distinct views (or held-out views) to solve and measure."""


@dataclass(frozen=True)
class SolveConfig:
    """Tunables of calibrate_pairs (see the module docstring)."""

    max_stereo_rms_px: float = 0.5
    max_epipolar_rms_px: float = 0.3
    min_views: int = 8
    max_views: int = 40
    holdout_every: int = 5
    min_holdout: int = 1
    min_distance: float = 0.2


@dataclass
class ViewRecord:
    """What happened to one input pair; errors are per-view RMS in px where they apply."""

    index: int
    label: str
    status: ViewStatus
    params: tuple[float, float, float, float] | None = None
    rms_left: float | None = None
    rms_right: float | None = None
    rms_stereo: tuple[float, float] | None = None
    epipolar_rms_px: float | None = None


@dataclass
class Rectification:
    """cv2.stereoRectify output for the solved head."""

    R1: np.ndarray
    R2: np.ndarray
    P1: np.ndarray
    P2: np.ndarray
    Q: np.ndarray


@dataclass
class CalibrationResult:
    """Everything the tool writes and reports."""

    calibration: StereoCalibration
    quality: CalibrationQuality
    rectification: Rectification
    views: list[ViewRecord]
    coverage: tuple[float, ...]
    failures: list[str] = field(default_factory=list)
    sample_pair: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def passed(self) -> bool:
        return not self.failures


@dataclass(frozen=True)
class Progress:
    """Reported after each input pair."""

    view: ViewRecord
    kept: int
    held_out: int
    coverage: tuple[float, ...]


def _gray(img: np.ndarray) -> np.ndarray:
    if img.dtype != np.uint8:
        raise ValueError(f"images must be uint8, got {img.dtype}")
    if img.ndim == 3:
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    if img.ndim != 2:
        raise ValueError(f"images must be HxW or HxWx3, got shape {img.shape}")
    return img


def detect_corners(img: np.ndarray, board: BoardSpec) -> np.ndarray | None:
    """Sub-pixel inner corners (cols*rows, 2) float32 in OpenCV order, or None if not found."""
    gray = _gray(img)
    found, corners = cv2.findChessboardCorners(
        gray, (board.cols, board.rows), flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not found:
        return None
    grid = corners.reshape(board.rows, board.cols, 2)
    spacing = min(np.linalg.norm(np.diff(grid, axis=0), axis=2).min(),
                  np.linalg.norm(np.diff(grid, axis=1), axis=2).min())
    half = int(np.clip(0.4 * spacing, 2, 15))
    corners = cv2.cornerSubPix(gray, corners, (half, half), (-1, -1), _SUBPIX)
    return corners.reshape(-1, 2).astype(np.float32)


def view_params(corners: np.ndarray, board: BoardSpec, image_size: tuple[int, int]) -> tuple[float, ...]:
    """ROS-style (X, Y, size, skew) of one view, each in [0, 1]."""
    w, h = image_size
    c = corners.reshape(-1, 2).astype(np.float64)
    ul, ur, dr, dl = c[0], c[board.cols - 1], c[-1], c[-board.cols]
    p, q = (dr - ur) + (dl - dr), (ur - ul) + (dr - ur)
    area = abs(p[0] * q[1] - p[1] * q[0]) / 2.0
    border = math.sqrt(area)
    x = min(1.0, max(0.0, (c[:, 0].mean() - border / 2) / (w - border)))
    y = min(1.0, max(0.0, (c[:, 1].mean() - border / 2) / (h - border)))
    a, b = ul - ur, dr - ur
    angle = math.acos(np.clip(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)), -1.0, 1.0))
    return (x, y, math.sqrt(area / (w * h)), min(1.0, 2.0 * abs(math.pi / 2 - angle)))


class CoverageSelector:
    """Keeps views that are far (L1 > min_distance) from all kept ones; tracks coverage."""

    def __init__(self, min_distance: float = 0.2) -> None:
        self.min_distance = min_distance
        self.kept: list[tuple[float, ...]] = []

    def offer(self, params: Sequence[float]) -> bool:
        """True (and remember it) when the view adds coverage."""
        if any(sum(abs(a - b) for a, b in zip(params, k)) <= self.min_distance for k in self.kept):
            return False
        self.kept.append(tuple(params))
        return True

    def coverage(self) -> tuple[float, ...]:
        """Per parameter: min(1, spread of kept views / PARAM_RANGES)."""
        if not self.kept:
            return (0.0,) * len(PARAM_RANGES)
        arr = np.array(self.kept)
        return tuple(float(min(1.0, s / r)) for s, r in zip(arr.max(0) - arr.min(0), PARAM_RANGES))


def _epipolar(l: np.ndarray, r: np.ndarray, calib: StereoCalibration, rect: Rectification) -> np.ndarray:
    """y_left_rect − y_right_rect per corner."""
    yl = cv2.undistortPoints(l.reshape(-1, 1, 2).astype(np.float64), calib.K_left, calib.D_left,
                             R=rect.R1, P=rect.P1, criteria=_UNDIST)[:, 0, 1]
    yr = cv2.undistortPoints(r.reshape(-1, 1, 2).astype(np.float64), calib.K_right, calib.D_right,
                             R=rect.R2, P=rect.P2, criteria=_UNDIST)[:, 0, 1]
    return yl - yr


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def _gate(calib: StereoCalibration, q: CalibrationQuality, config: SolveConfig) -> list[str]:
    failures = []
    if q.rms_stereo > config.max_stereo_rms_px:
        failures.append(f"stereo RMS {q.rms_stereo:.3f} px > {config.max_stereo_rms_px} px")
    if q.epipolar_rms_px > config.max_epipolar_rms_px:
        failures.append(f"held-out epipolar RMS {q.epipolar_rms_px:.3f} px > {config.max_epipolar_rms_px} px")
    w, h = calib.image_size
    for side, K in (("left", calib.K_left), ("right", calib.K_right)):
        if not (0 <= K[0, 2] < w and 0 <= K[1, 2] < h):
            failures.append(f"{side} principal point ({K[0, 2]:.1f}, {K[1, 2]:.1f}) outside the image")
        if abs(K[0, 0] / K[1, 1] - 1) > 0.05:
            failures.append(f"{side} fx/fy = {K[0, 0] / K[1, 1]:.3f} is implausible")
    return failures


def calibrate_pairs(pairs: Iterable[tuple[np.ndarray, np.ndarray]], board: BoardSpec,
                    config: SolveConfig = SolveConfig(), labels: Sequence[str] | None = None,
                    progress: Callable[[Progress], None] | None = None) -> CalibrationResult:
    """Calibrate a stereo head from raw image pairs of `board` (see the module docstring).

    Raises BoardNotFoundError / TooFewViewsError when no solution can be computed, ValueError on
    inconsistent images; a solution that fails the gate is returned with `failures` set.
    """
    if board.cols == board.rows:
        raise ValueError("use a board with cols != rows so its orientation is unambiguous")
    selector = CoverageSelector(config.min_distance)
    views: list[ViewRecord] = []
    used: list[tuple[np.ndarray, np.ndarray]] = []
    held: list[tuple[np.ndarray, np.ndarray, ViewRecord]] = []
    sample: tuple[np.ndarray, np.ndarray] | None = None
    size: tuple[int, int] | None = None
    found_left = found_right = both = 0
    for index, (left, right) in enumerate(pairs):
        left, right = _gray(left), _gray(right)
        if left.shape != right.shape or (size is not None and left.shape[::-1] != size):
            raise ValueError(f"pair {index}: image sizes differ ({left.shape}, {right.shape}, first {size})")
        size = (left.shape[1], left.shape[0])
        label = labels[index] if labels is not None else f"pair {index}"
        cl, cr = detect_corners(left, board), detect_corners(right, board)
        found_left, found_right = found_left + (cl is not None), found_right + (cr is not None)
        view = ViewRecord(index, label, "no_board")
        if cl is not None and cr is not None:
            both += 1
            if np.dot(cl[-1] - cl[0], cr[-1] - cr[0]) < 0:
                cr = cr[::-1].copy()
            view.params = view_params(cl, board, size)
            if both % config.holdout_every == 0:
                view.status = "held_out"
                held.append((cl, cr, view))
                sample = sample or (left, right)
            elif selector.offer(view.params):
                view.status = "used"
                used.append((cl, cr))
            else:
                view.status = "redundant"
        views.append(view)
        if progress is not None:
            progress(Progress(view, len(used), len(held), selector.coverage()))
        if len(used) >= config.max_views and len(held) >= config.min_holdout:
            break
    if both == 0:
        raise BoardNotFoundError(
            f"the {board.cols}x{board.rows} chessboard was not found in both images of any of the "
            f"{len(views)} pairs (left found {found_left}, right found {found_right})")
    if len(used) < config.min_views or len(held) < config.min_holdout:
        raise TooFewViewsError(
            f"{len(used)} distinct views and {len(held)} held-out pairs from {both} pairs with the board; "
            f"need {config.min_views} and {config.min_holdout} — move the board to new positions, "
            f"distances and tilts")
    return _solve(used, held, views, board, size, selector.coverage(), sample, config)


def _solve(used: list[tuple[np.ndarray, np.ndarray]], held: list[tuple[np.ndarray, np.ndarray, ViewRecord]],
           views: list[ViewRecord], board: BoardSpec, size: tuple[int, int], coverage: tuple[float, ...],
           sample: tuple[np.ndarray, np.ndarray] | None, config: SolveConfig) -> CalibrationResult:
    obj = [board.object_points()] * len(used)
    img_l = [l.reshape(-1, 1, 2) for l, _ in used]
    img_r = [r.reshape(-1, 1, 2) for _, r in used]
    try:
        rms_l, K1, D1, *_, err_l = cv2.calibrateCameraExtended(obj, img_l, size, None, None, criteria=_SOLVE)
        rms_r, K2, D2, *_, err_r = cv2.calibrateCameraExtended(obj, img_r, size, None, None, criteria=_SOLVE)
        rms_s, K1, D1, K2, D2, R, T, *_, err_s = cv2.stereoCalibrateExtended(
            obj, img_l, img_r, K1, D1, K2, D2, size, None, None, flags=cv2.CALIB_FIX_INTRINSIC, criteria=_SOLVE)
        calib = StereoCalibration(size, K1, D1, K2, D2, R, T)
        R1, R2, P1, P2, Q, *_ = cv2.stereoRectify(K1, D1, K2, D2, size, R, T, flags=cv2.CALIB_ZERO_DISPARITY,
                                                  alpha=0)
    except (cv2.error, ValueError) as exc:
        raise CalibrationError(f"the solver failed on {len(used)} views: {exc}") from exc
    rect = Rectification(R1, R2, P1, P2, Q)
    used_views = iter(v for v in views if v.status == "used")
    for i, v in enumerate(used_views):
        v.rms_left, v.rms_right = float(err_l[i, 0]), float(err_r[i, 0])
        v.rms_stereo = (float(err_s[i, 0]), float(err_s[i, 1]))
    dy_all = []
    for cl, cr, v in held:
        dy = _epipolar(cl, cr, calib, rect)
        v.epipolar_rms_px = _rms(dy)
        dy_all.append(dy)
    quality = CalibrationQuality(rms_left=float(rms_l), rms_right=float(rms_r), rms_stereo=float(rms_s),
                                 epipolar_rms_px=_rms(np.concatenate(dy_all)), views_used=len(used),
                                 written=False, verified=False)
    failures = _gate(calib, quality, config)
    quality.passed = not failures
    return CalibrationResult(calib, quality, rect, views, coverage, failures, sample)
