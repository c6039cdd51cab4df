"""Live-capture view selection (ROS camera_calibration style): each view's (X, Y, size, skew) and
the selector that keeps only views far from every kept one (see tools/calibration/solve.py, step 2)."""
from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np

from stereocam.stereo.calibration_board import BoardSpec
from stereocam.tools.calibration.boards import Board

PARAM_NAMES = ("X", "Y", "Size", "Skew")
PARAM_RANGES = (0.7, 0.7, 0.4, 0.5)


def view_params(corners: np.ndarray, board: Board, image_size: tuple[int, int]
                ) -> tuple[float, ...]:
    """ROS-style (X, Y, size, skew) of one view, each in [0, 1] (ChArUco, AprilGrid: hull area, skew 0)."""
    w, h = image_size
    c = corners.reshape(-1, 2).astype(np.float64)
    if not isinstance(board, BoardSpec):
        area = float(cv2.contourArea(cv2.convexHull(c.astype(np.float32))))
        border = math.sqrt(area)
        x = min(1.0, max(0.0, (c[:, 0].mean() - border / 2) / max(w - border, 1.0)))
        y = min(1.0, max(0.0, (c[:, 1].mean() - border / 2) / max(h - border, 1.0)))
        return (x, y, math.sqrt(area / (w * h)), 0.0)
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
