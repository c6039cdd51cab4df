"""Rectified geometry of a stored calibration — shared by the device (which builds its
rectification maps from it) and the host (which turns disparity into depth with it).

stereo_rectify(calib) reproduces cv2.stereoRectify(K1, D1, K2, D2, size, R, T,
flags=CALIB_ZERO_DISPARITY, alpha=0) for a horizontal head:
  * each camera turns by half of R (r_r = rodrigues(−½·rodrigues⁻¹(R))), then both by the rotation
    that brings t = r_r·T onto the ±x axis: R1 = wR·r_rᵀ, R2 = wR·r_r;
  * focal f = mean of the two fy, then scaled so that only valid pixels remain (alpha = 0: the
    largest of the per-side ratios between the image half-extents and the inner rectangle of the
    undistorted, rotated image border sampled at 9 points per side);
  * principal point: the point that centres the undistorted image corners, averaged over both
    cameras (zero disparity: cx and cy are equal in P1 and P2, so Q[3][3] = 0 and Z = f·B/d).
    plumb_bob points are undistorted with OpenCV's 5 fixed-point steps in these two places, as it
    does; rational_polynomial points with fixed-point steps run to convergence (5 steps leave
    pixels of error on the wide-angle lenses that need that model), equidistant (fisheye) points
    exactly (Newton on θ): for those two models the geometry is this function's, not OpenCV's.
  * P1 = [f 0 cx 0; 0 f cy 0; 0 0 1 0], P2 = P1 with P2[0,3] = −f·B (B = baseline, metres);
    Q = [1 0 0 −cx; 0 1 0 −cy; 0 0 0 f; 0 0 1/B 0].
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .calibration import StereoCalibration

_OPENCV_UNDISTORT_STEPS = 5
_CONVERGED_STEPS = 200  # fixed-point steps stop earlier once a step moves < 1e-14


def rodrigues(rvec: np.ndarray) -> np.ndarray:
    """Rotation matrix of an axis-angle vector (radians)."""
    theta = float(np.linalg.norm(rvec))
    if theta == 0.0:
        return np.eye(3)
    k = rvec / theta
    Kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(theta) * Kx + (1.0 - np.cos(theta)) * Kx @ Kx


@dataclass(frozen=True)
class RectifiedGeometry:
    """The rectified stereo head: rotations, projections, Q and their scalars."""

    image_size: tuple[int, int]
    R1: np.ndarray
    R2: np.ndarray
    P1: np.ndarray
    P2: np.ndarray
    Q: np.ndarray

    @property
    def focal_px(self) -> float:
        return float(self.P1[0, 0])

    @property
    def cx(self) -> float:
        return float(self.P1[0, 2])

    @property
    def cy(self) -> float:
        return float(self.P1[1, 2])

    @property
    def baseline_m(self) -> float:
        return float(-self.P2[0, 3] / self.P2[0, 0])


def _log_rotation(R: np.ndarray) -> np.ndarray:
    """Axis-angle vector of a rotation matrix (inverse of rodrigues)."""
    cos = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
    theta = float(np.arccos(cos))
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if theta < 1e-12:
        return axis / 2.0
    if np.pi - theta < 1e-6:  # near π the skew part vanishes: the axis is R's +1 eigenvector
        values, vectors = np.linalg.eigh((R + R.T) / 2.0)
        return theta * vectors[:, np.argmax(values)]
    return theta * axis / (2.0 * np.sin(theta))


def _undistort_pinhole(D: np.ndarray, x0: np.ndarray, y0: np.ndarray, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's fixed-point undistortion for plumb_bob (5) and rational_polynomial (8) coefficients."""
    k1, k2, p1, p2, k3, k4, k5, k6 = (*D, 0.0, 0.0, 0.0)[:8]
    x, y = x0.copy(), y0.copy()
    for _ in range(steps):
        with np.errstate(all="ignore"):  # far outside a rational lens's valid field: inf / NaN, judged by callers
            r2 = x * x + y * y
            icdist = (1.0 + ((k6 * r2 + k5) * r2 + k4) * r2) / (1.0 + ((k3 * r2 + k2) * r2 + k1) * r2)
            nx, ny = ((x0 - (2 * p1 * x * y + p2 * (r2 + 2 * x * x))) * icdist,
                      (y0 - (p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)) * icdist)
        done = np.all(np.abs(nx - x) < 1e-14) and np.all(np.abs(ny - y) < 1e-14)
        x, y = nx, ny
        if done:
            break
    return x, y


def _undistort_equidistant(D: np.ndarray, x0: np.ndarray, y0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Invert θ_d = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸) by Newton's method (to 1e-12 rad)."""
    k1, k2, k3, k4 = D
    theta_d = np.hypot(x0, y0)
    theta = theta_d.copy()
    for _ in range(50):
        t2 = theta * theta
        f = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - theta_d
        df = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + 9 * k4 * t2)))
        step = f / df
        theta = theta - step
        if np.all(np.abs(step) < 1e-12):
            break
    scale = np.where(theta_d > 1e-12, np.tan(theta) / np.maximum(theta_d, 1e-300), 1.0)
    return x0 * scale, y0 * scale


def undistort_points(K: np.ndarray, D: np.ndarray, pts: np.ndarray, steps: int,
                     lens_model: str = "plumb_bob") -> np.ndarray:
    """Normalised undistorted coordinates (N, 2) of pixel points.

    plumb_bob / rational_polynomial: `steps` fixed-point iterations (OpenCV uses 5 inside
    stereoRectify; use more to converge); equidistant: converged whatever `steps`.
    """
    x0 = (pts[:, 0] - K[0, 2]) / K[0, 0]
    y0 = (pts[:, 1] - K[1, 2]) / K[1, 1]
    if lens_model == "equidistant":
        x, y = _undistort_equidistant(np.asarray(D, np.float64), x0, y0)
    else:
        x, y = _undistort_pinhole(np.asarray(D, np.float64), x0, y0, steps)
    return np.column_stack([x, y])


def _project(xy: np.ndarray, R: np.ndarray, f: float, cx: float, cy: float) -> np.ndarray:
    p = np.column_stack([xy, np.ones(len(xy))]) @ R.T
    return np.column_stack([f * p[:, 0] / p[:, 2] + cx, f * p[:, 1] / p[:, 2] + cy])


def stereo_rectify(calib: StereoCalibration) -> RectifiedGeometry:
    """Rectified geometry of a horizontal head (see the module docstring)."""
    w, h = calib.image_size
    r_r = rodrigues(-0.5 * _log_rotation(calib.R))
    t = r_r @ calib.T
    if abs(t[0]) <= abs(t[1]):
        raise ValueError("only horizontal stereo heads are supported (|Tx| must exceed |Ty|)")
    uu = np.array([1.0 if t[0] > 0 else -1.0, 0.0, 0.0])
    ww = np.cross(t, uu)
    nw = np.linalg.norm(ww)
    if nw > 0:
        ww *= np.arccos(abs(t[0]) / np.linalg.norm(t)) / nw
    wR = rodrigues(ww)
    R1, R2 = wR @ r_r.T, wR @ r_r
    tx = float((R2 @ calib.T)[0])
    cams = ((calib.K_left, calib.D_left, R1), (calib.K_right, calib.D_right, R2))
    model = calib.lens_model
    steps = _OPENCV_UNDISTORT_STEPS if model == "plumb_bob" else _CONVERGED_STEPS
    f = (calib.K_left[1, 1] + calib.K_right[1, 1]) * 0.5
    corners = np.array([[0.0, 0.0], [w - 1, 0.0], [0.0, h - 1], [w - 1, h - 1]])
    centres = [np.array([(w - 1) / 2, (h - 1) / 2]) -
               _project(undistort_points(K, D, corners, steps, model), Rk, f, 0.0, 0.0).mean(axis=0)
               for K, D, Rk in cams]
    cx, cy = (centres[0] + centres[1]) * 0.5
    # alpha = 0: zoom until the inner rectangle of both undistorted image borders fills the frame
    # (as OpenCV 5 samples it: 9 points per side from pixel 0 to pixel w-1 / h-1, corners included)
    a = np.linspace(0.0, 1.0, 9)
    sides = [np.column_stack([np.zeros(9), a * (h - 1)]), np.column_stack([np.full(9, w - 1.0), a * (h - 1)]),
             np.column_stack([a * (w - 1), np.zeros(9)]), np.column_stack([a * (w - 1), np.full(9, h - 1.0)])]
    s = -np.inf
    for K, D, Rk in cams:
        left, right, top, bottom = (_project(undistort_points(K, D, side, steps, model), Rk, f, cx, cy)
                                    for side in sides)
        ix0, ix1, iy0, iy1 = left[:, 0].max(), right[:, 0].min(), top[:, 1].max(), bottom[:, 1].min()
        s = max(s, cx / (cx - ix0), cy / (cy - iy0), (w - 1 - cx) / (ix1 - cx), (h - 1 - cy) / (iy1 - cy))
    f *= s
    P1 = np.array([[f, 0.0, cx, 0.0], [0.0, f, cy, 0.0], [0.0, 0.0, 1.0, 0.0]])
    P2 = P1.copy()
    P2[0, 3] = tx * f
    Q = np.array([[1.0, 0.0, 0.0, -cx], [0.0, 1.0, 0.0, -cy], [0.0, 0.0, 0.0, f], [0.0, 0.0, -1.0 / tx, 0.0]])
    return RectifiedGeometry((w, h), R1, R2, P1, P2, Q)
