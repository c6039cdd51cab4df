"""report.png for a calibration: metrics, per-view errors, coverage bars, a rectified pair."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from stereocam.device_sim.calibration.rectify import undistort_rectify_map
from stereocam.tools.calib_coverage import PARAM_NAMES
from stereocam.tools.calib_solve import CalibrationResult

WIDTH = 1280
_FONT = cv2.FONT_HERSHEY_SIMPLEX
_WHITE, _GREY, _BLACK = (255, 255, 255), (160, 160, 160), (0, 0, 0)
_LEFT, _RIGHT, _EPI = (200, 120, 40), (60, 170, 60), (30, 140, 240)  # BGR


def _text(img: np.ndarray, text: str, xy: tuple[int, int], scale: float = 0.5, color=_BLACK) -> None:
    cv2.putText(img, text, xy, _FONT, scale, color, 1, cv2.LINE_AA)


def _header(result: CalibrationResult) -> np.ndarray:
    img = np.full((70, WIDTH, 3), 255, np.uint8)
    q, c = result.quality, result.calibration
    verdict = "PASSED" if result.passed else "FAILED: " + "; ".join(result.failures)
    _text(img, verdict, (10, 25), 0.7, (0, 140, 0) if result.passed else (0, 0, 200))
    _text(img, f"rms left {q.rms_left:.3f} px   right {q.rms_right:.3f} px   stereo {q.rms_stereo:.3f} px   "
               f"held-out epipolar {q.epipolar_rms_px:.3f} px   pairs {q.views_used} (+{q.views_dropped} dropped)   "
               f"{c.lens_model}   baseline {c.baseline_m * 1000:.2f} mm   {c.image_size[0]}x{c.image_size[1]}",
          (10, 55))
    return img


def _view_errors(result: CalibrationResult, height: int = 240) -> np.ndarray:
    """Bars per used pair: left/right reprojection RMS, and for held-out pairs their epipolar RMS."""
    img = np.full((height, WIDTH, 3), 255, np.uint8)
    views = [v for v in result.views if v.status == "used"]
    values = [x for v in views for x in (v.rms_left, v.rms_right, v.epipolar_rms_px if v.held_out else None)
              if x is not None]
    top = max(0.2, 1.1 * max(values, default=0.0))
    x0, y0, y1 = 60, 30, height - 30
    plot_w = WIDTH - x0 - 20
    for k in range(5):
        y = int(y1 - (y1 - y0) * k / 4)
        cv2.line(img, (x0, y), (WIDTH - 20, y), (225, 225, 225), 1)
        _text(img, f"{top * k / 4:.2f}", (5, y + 4), 0.4)
    slot = plot_w / max(len(views), 1)
    bar = max(1, int(slot / 4) - 1)

    def draw(i: int, k: int, value: float, color: tuple[int, int, int]) -> None:
        x = int(x0 + i * slot + k * (bar + 1))
        cv2.rectangle(img, (x, int(y1 - (y1 - y0) * value / top)), (x + bar - 1, y1), color, -1)

    for i, v in enumerate(views):
        draw(i, 0, v.rms_left, _LEFT)
        draw(i, 1, v.rms_right, _RIGHT)
        if v.held_out:
            draw(i, 2, v.epipolar_rms_px, _EPI)
    _text(img, "per-view RMS error (px):", (10, 18))
    for k, (name, color) in enumerate((("left reprojection", _LEFT), ("right reprojection", _RIGHT),
                                       ("held-out epipolar", _EPI))):
        cv2.rectangle(img, (260 + 200 * k, 8), (272 + 200 * k, 20), color, -1)
        _text(img, name, (278 + 200 * k, 19))
    return img


def _coverage(result: CalibrationResult) -> np.ndarray:
    img = np.full((30 * len(PARAM_NAMES) + 30, WIDTH, 3), 255, np.uint8)
    _text(img, "coverage of the pairs used (ROS-style X, Y, size, skew):", (10, 18))
    for k, (name, value) in enumerate(zip(PARAM_NAMES, result.coverage)):
        y = 30 + 30 * k
        _text(img, name, (10, y + 16))
        cv2.rectangle(img, (70, y), (70 + 400, y + 20), _GREY, 1)
        cv2.rectangle(img, (70, y), (70 + int(400 * value), y + 20), (0, 160, 0) if value >= 1 else _EPI, -1)
        _text(img, f"{100 * value:.0f} %", (480, y + 16))
    return img


def _rectified_pair(result: CalibrationResult) -> np.ndarray | None:
    if result.sample_pair is None:
        return None
    c, r = result.calibration, result.rectification
    halves = []
    for img, K, D, R, P in ((result.sample_pair[0], c.K_left, c.D_left, r.R1, r.P1),
                            (result.sample_pair[1], c.K_right, c.D_right, r.R2, r.P2)):
        mx, my = undistort_rectify_map(K, D, R, P, c.image_size, c.lens_model)
        halves.append(cv2.remap(img, mx, my, cv2.INTER_LINEAR))
    pair = cv2.cvtColor(np.hstack(halves), cv2.COLOR_GRAY2BGR)
    scale = WIDTH / pair.shape[1]
    pair = cv2.resize(pair, (WIDTH, int(round(pair.shape[0] * scale))), interpolation=cv2.INTER_AREA)
    for y in range(20, pair.shape[0], 30):
        cv2.line(pair, (0, y), (WIDTH - 1, y), (0, 200, 255), 1)
    cv2.line(pair, (WIDTH // 2, 0), (WIDTH // 2, pair.shape[0] - 1), _WHITE, 2)
    _text(pair, "rectified pair with epipolar lines", (10, 18), 0.5, _WHITE)
    return pair


def write_report(result: CalibrationResult, path: Path) -> None:
    """Render the report and write it as a PNG."""
    parts = [_header(result), _view_errors(result), _coverage(result)]
    pair = _rectified_pair(result)
    if pair is not None:
        parts.append(pair)
    if not cv2.imwrite(str(path), np.vstack(parts)):
        raise OSError(f"cannot write {path}")
