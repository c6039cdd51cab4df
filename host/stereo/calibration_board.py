"""Chessboard calibration target geometry, for calibration tools and the simulator alike (no I/O).

Board frame: origin at the first inner corner, x along a row of `cols` inner corners, y along the
`rows` direction, z = 0 on the printed face. Inner corner (i, j) sits at (i·s, j·s, 0) — the order
of BoardSpec.object_points() and of cv2.findChessboardCorners for pattern size (cols, rows). The
board has (cols+1)×(rows+1) squares, the corner ones black, inside a white margin of
`margin_squares`. A pose (R, t) maps board to camera: X_cam = R @ X_board + t (the convention of
cv2.solvePnP).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stereocam.protocol.errors import ConfigError


@dataclass(frozen=True)
class BoardSpec:
    """Chessboard with cols×rows inner corners and square side square_m metres."""

    cols: int
    rows: int
    square_m: float
    margin_squares: float = 1.0

    def __post_init__(self) -> None:
        if self.cols < 2 or self.rows < 2 or self.square_m <= 0 or self.margin_squares < 0:
            raise ConfigError(f"bad board {self.cols}x{self.rows} square {self.square_m} m")

    def object_points(self) -> np.ndarray:
        """Inner corners in the board frame, (cols*rows, 3) float32, x fastest."""
        j, i = np.mgrid[0:self.rows, 0:self.cols]
        pts = np.column_stack([i.ravel(), j.ravel(), np.zeros(i.size)]) * self.square_m
        return pts.astype(np.float32)

    def outline(self) -> np.ndarray:
        """The 4 corners of the board's white margin in the board frame, (4, 3)."""
        lo = -(1.0 + self.margin_squares) * self.square_m
        hx = (self.cols + self.margin_squares) * self.square_m
        hy = (self.rows + self.margin_squares) * self.square_m
        return np.array([[lo, lo, 0.0], [hx, lo, 0.0], [hx, hy, 0.0], [lo, hy, 0.0]])


@dataclass(frozen=True)
class BoardPose:
    """Board-to-left-camera transform: X_cam = R @ X_board + t (metres)."""

    R: np.ndarray
    t: np.ndarray
