"""Viewing rays of a distorted pinhole camera (the renderer casts these to make raw images).

pixel_rays inverts OpenCV's 5-coefficient distortion model
    r² = x² + y²,  x_d = x (1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2 x²)
                   y_d = y (1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2 y²) + 2 p2 x y
    u = fx x_d + cx,  v = fy y_d + cy
by fixed-point iteration run to convergence (|Δ| < 1e-13 in normalised units, at most 200 steps).
lens_rays / lens_project do the same for every lens model of SPEC §12.7 (the simulated wide-angle and
fisheye units, rig/lens.py).
"""
from __future__ import annotations

import numba
import numpy as np

from stereocam.protocol.rectification import rectified_to_raw, viewing_rays

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


def lens_rays(K: np.ndarray, D: np.ndarray, lens_model: str, width: int, height: int,
              supersample: int = 1) -> np.ndarray:
    """Viewing rays float32 (H*s, W*s, 3) of a camera of any lens model (SPEC §12.7), sub-pixels as
    pixel_rays lays them out. plumb_bob: pixel_rays (z = 1); rational_polynomial: (x, y, 1) from the
    fixed-point inversion run to convergence; equidistant: unit rays from Newton on θ, valid beyond
    90° off axis (pointing backwards)."""
    if lens_model == "plumb_bob":
        return pixel_rays(K, D, width, height, supersample)
    step = 1.0 / supersample
    u = 0.5 * step - 0.5 + step * np.arange(width * supersample)
    v = 0.5 * step - 0.5 + step * np.arange(height * supersample)
    uu, vv = np.meshgrid(u, v)
    pts = np.column_stack([uu.ravel(), vv.ravel()])
    rays = viewing_rays(np.asarray(K, np.float64), np.asarray(D, np.float64), pts, 200, lens_model)
    return rays.reshape(len(v), len(u), 3).astype(np.float32)


def lens_project(K: np.ndarray, D: np.ndarray, lens_model: str, points: np.ndarray) -> np.ndarray:
    """Pixel positions (N, 2) of camera-frame points (N, 3) through a lens of any model."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if lens_model == "plumb_bob":
        return project_points(K, D, p)
    if lens_model == "equidistant":  # any direction, also behind the lens
        return _project_equidistant(K, D, p)
    with np.errstate(divide="ignore", invalid="ignore"):  # the identity view's map is the lens projection
        return rectified_to_raw(K, D, lens_model, np.eye(3), np.hstack([np.eye(3), np.zeros((3, 1))]),
                                p[:, :2] / p[:, 2:])


def _project_equidistant(K: np.ndarray, D: np.ndarray, p: np.ndarray) -> np.ndarray:
    k1, k2, k3, k4 = np.asarray(D, np.float64).ravel()
    r = np.hypot(p[:, 0], p[:, 1])
    theta = np.arctan2(r, p[:, 2])
    t2 = theta * theta
    theta_d = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
    s = np.where(r > 0, theta_d / np.maximum(r, 1e-300), 0.0)
    return np.column_stack([K[0, 0] * p[:, 0] * s + K[0, 2], K[1, 1] * p[:, 1] * s + K[1, 2]])
