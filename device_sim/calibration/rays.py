"""Viewing rays of a distorted pinhole camera (the renderer casts these to make raw images).

pixel_rays inverts OpenCV's 5-coefficient distortion model
    r² = x² + y²,  x_d = x (1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2 x²)
                   y_d = y (1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2 y²) + 2 p2 x y
    u = fx x_d + cx,  v = fy y_d + cy
by fixed-point iteration run to convergence (|Δ| < 1e-13 in normalised units, at most 200 steps).
"""
from __future__ import annotations

import numba
import numpy as np

_MAX_ITER = 200
_TOL = 1e-13


@numba.njit(parallel=True, nogil=True, cache=True)
def _rays(fx: float, fy: float, cx: float, cy: float, dist: np.ndarray, width: int, height: int,
          step: float, start: float) -> np.ndarray:
    k1, k2, p1, p2, k3 = dist[0], dist[1], dist[2], dist[3], dist[4]
    out = np.empty((height, width, 3), dtype=np.float32)
    for j in numba.prange(height):
        yd = (start + j * step - cy) / fy
        for i in range(width):
            xd = (start + i * step - cx) / fx
            x, y = xd, yd
            for _ in range(_MAX_ITER):
                r2 = x * x + y * y
                icdist = 1.0 / (1.0 + ((k3 * r2 + k2) * r2 + k1) * r2)
                nx = (xd - (2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x))) * icdist
                ny = (yd - (p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y)) * icdist
                done = abs(nx - x) < _TOL and abs(ny - y) < _TOL
                x, y = nx, ny
                if done:
                    break
            out[j, i, 0] = x
            out[j, i, 1] = y
            out[j, i, 2] = 1.0
    return out


def pixel_rays(K: np.ndarray, D: np.ndarray, width: int, height: int, supersample: int = 1) -> np.ndarray:
    """Ray directions (x, y, 1) in the camera frame, float32 of shape (H*s, W*s, 3).

    With supersample s > 1 the rays go through the centres of an s×s grid of sub-pixels in each
    pixel: pixel (u, v) owns sub-pixel rays [v*s:(v+1)*s, u*s:(u+1)*s] at positions
    u + (a + 0.5)/s - 0.5, a = 0..s-1 (likewise in v).
    """
    K = np.asarray(K, dtype=np.float64)
    D = np.asarray(D, dtype=np.float64).reshape(-1)
    if K.shape != (3, 3) or D.shape != (5,):
        raise ValueError(f"K must be 3x3 and D have 5 coefficients, got {K.shape} and {D.shape}")
    if K[0, 1] != 0:
        raise ValueError("skewed camera matrices are not supported")
    if width <= 0 or height <= 0 or supersample < 1:
        raise ValueError(f"bad ray grid {width}x{height} supersample {supersample}")
    step = 1.0 / supersample
    return _rays(K[0, 0], K[1, 1], K[0, 2], K[1, 2], D, width * supersample, height * supersample,
                 step, 0.5 * step - 0.5)


def project_points(K: np.ndarray, D: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Pixel positions (N, 2) of camera-frame points (N, 3) under the distortion model above."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    k1, k2, p1, p2, k3 = np.asarray(D, dtype=np.float64).reshape(5)
    x, y = p[:, 0] / p[:, 2], p[:, 1] / p[:, 2]
    r2 = x * x + y * y
    radial = 1.0 + ((k3 * r2 + k2) * r2 + k1) * r2
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.column_stack([K[0, 0] * xd + K[0, 2], K[1, 1] * yd + K[1, 2]])
