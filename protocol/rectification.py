"""Rectified geometry of a stored calibration — shared by the device (which builds its
rectification maps from it) and the host (which turns disparity into depth with it). SPEC §12.6
states the same algorithm step by step; protocol/golden/rectification.json holds its vectors.

stereo_rectify(calib), for a horizontal head (|Tx| > |Ty| after step 1), all in float64:
  1. Rotations (every lens model): r = −½·log(R) (axis-angle), r_r = rodrigues(r); t = r_r·T;
     e = (sign(t_x), 0, 0); w = (t × e)/|t × e| · acos(|t_x|/|t|) (w = 0 when t × e = 0);
     R1 = rodrigues(w)·r_rᵀ, R2 = rodrigues(w)·r_r; B = −(R2·T)_x (> 0 for T_x < 0).
  2. Border samples (every model): 9 points per image side, pixel 0 to pixel W−1 (H−1), corners
     included; each is undistorted to its viewing ray (see undistort_points / _equidistant_rays) and
     turned by its camera's R1 or R2.
  3. Focal and principal point —
     pinhole models (plumb_bob, rational_polynomial; cv2.stereoRectify(alpha=0,
     CALIB_ZERO_DISPARITY) for plumb_bob): f0 = mean of the two fy; (cx, cy) = the mean over both
     cameras of (W−1)/2 − mean(f0·x'/z' of the four corners), likewise y; then f = f0·s, s the
     largest of the four ratios (half-extent of the image from (cx, cy)) / (extent of the inner
     rectangle of the projected border, f0-scaled) over both cameras — every rectified pixel sees
     the sensor. plumb_bob rays come from OpenCV's 5 fixed-point steps, rational_polynomial rays from
     fixed-point steps to convergence (|Δ| < 1e-14).
     equidistant: (cx, cy) = ((W−1)/2, (H−1)/2); f = max(f_fov, f_in): f_fov = (W/2)/tan(fov/2)
     gives the output field of view (the device parameter ``rectified_fov``, SPEC §5.1; its default
     EQUIDISTANT_FOV_DEG lets a 180° or wider lens keep a usable pinhole view), f_in is the
     smallest focal whose view stays inside the inner rectangle of the turned border rays (a ray
     at ≥ 90° from the rectified axis, z' ≤ 0, or on the far side of the axis bounds nothing), so
     narrow equidistant lenses still show only valid pixels. Rays: Newton on θ to 1e-12 rad.
  4. P1 = [f 0 cx 0; 0 f cy 0; 0 0 1 0], P2 = P1 with P2[0,3] = −f·B;
     Q = [1 0 0 −cx; 0 1 0 −cy; 0 0 0 f; 0 0 1/B 0] (Z = f·B/d).
rectified_to_raw() is the map each camera's remap table samples (SPEC §12.6, step 5).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .calibration import StereoCalibration
from .params import BY_NAME

_OPENCV_UNDISTORT_STEPS = 5
CONVERGED_STEPS = 200  # fixed-point steps stop earlier once a step moves < 1e-14
EQUIDISTANT_FOV_DEG = float(BY_NAME["rectified_fov"].default)
"""Default horizontal field of view (edge to edge of the image width) of a rectified equidistant view
(the device parameter ``rectified_fov`` picks another)."""
BORDER_SAMPLES = 9  # points per image side, corners included (OpenCV's sampling)


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


def _equidistant_theta(D: np.ndarray, theta_d: np.ndarray) -> np.ndarray:
    """Invert θ_d = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸) by Newton's method from θ = θ_d (to 1e-12 rad)."""
    k1, k2, k3, k4 = D
    theta = theta_d.copy()
    for _ in range(50):
        t2 = theta * theta
        f = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - theta_d
        df = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + 9 * k4 * t2)))
        step = f / df
        theta = theta - step
        if np.all(np.abs(step) < 1e-12):
            break
    return theta


def _equidistant_rays(D: np.ndarray, x0: np.ndarray, y0: np.ndarray) -> np.ndarray:
    """Unit viewing rays (N, 3) of normalised distorted points of an equidistant lens (any angle)."""
    theta_d = np.hypot(x0, y0)
    theta = _equidistant_theta(D, theta_d)
    s = np.where(theta_d > 1e-12, np.sin(theta) / np.maximum(theta_d, 1e-300), 1.0)
    return np.column_stack([x0 * s, y0 * s, np.cos(theta)])


def undistort_points(K: np.ndarray, D: np.ndarray, pts: np.ndarray, steps: int,
                     lens_model: str = "plumb_bob") -> np.ndarray:
    """Normalised undistorted coordinates (N, 2) of pixel points.

    plumb_bob / rational_polynomial: `steps` fixed-point iterations (OpenCV uses 5 inside
    stereoRectify; use more to converge); equidistant: converged whatever `steps` (rays at or
    beyond 90° off axis have no such coordinates: use viewing_rays).
    """
    rays = viewing_rays(K, D, pts, steps, lens_model)
    with np.errstate(divide="ignore", invalid="ignore"):
        return rays[:, :2] / rays[:, 2:]


def viewing_rays(K: np.ndarray, D: np.ndarray, pts: np.ndarray, steps: int,
                 lens_model: str = "plumb_bob") -> np.ndarray:
    """Viewing rays (N, 3) of pixel points: (x, y, 1) for the pinhole models, unit for equidistant."""
    x0 = (pts[:, 0] - K[0, 2]) / K[0, 0]
    y0 = (pts[:, 1] - K[1, 2]) / K[1, 1]
    D = np.asarray(D, np.float64).ravel()
    if lens_model == "equidistant":
        return _equidistant_rays(D, x0, y0)
    x, y = _undistort_pinhole(D, x0, y0, steps)
    return np.column_stack([x, y, np.ones(len(x))])


def _turned(rays: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole coordinates (x'/z', y'/z') of rays turned by R; NaN where z' ≤ 0 (no pinhole image)."""
    p = rays @ R.T
    with np.errstate(divide="ignore", invalid="ignore"):
        ok = p[:, 2] > 0
        return np.where(ok, p[:, 0] / p[:, 2], np.nan), np.where(ok, p[:, 1] / p[:, 2], np.nan)


def _border(w: int, h: int) -> tuple[np.ndarray, ...]:
    """(left, right, top, bottom) sides: BORDER_SAMPLES pixel points each, corners included."""
    a = np.linspace(0.0, 1.0, BORDER_SAMPLES)
    n = BORDER_SAMPLES
    return (np.column_stack([np.zeros(n), a * (h - 1)]), np.column_stack([np.full(n, w - 1.0), a * (h - 1)]),
            np.column_stack([a * (w - 1), np.zeros(n)]), np.column_stack([a * (w - 1), np.full(n, h - 1.0)]))


def _rotations(calib: StereoCalibration) -> tuple[np.ndarray, np.ndarray, float]:
    """Step 1: R1, R2 and the signed rectified baseline t_x = (R2·T)_x."""
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
    return R1, R2, float((R2 @ calib.T)[0])


def _pinhole_view(calib: StereoCalibration, R1: np.ndarray, R2: np.ndarray) -> tuple[float, float, float]:
    """Step 3 for plumb_bob / rational_polynomial: (f, cx, cy)."""
    w, h = calib.image_size
    model = calib.lens_model
    steps = _OPENCV_UNDISTORT_STEPS if model == "plumb_bob" else CONVERGED_STEPS
    cams = ((calib.K_left, calib.D_left, R1), (calib.K_right, calib.D_right, R2))
    f = (calib.K_left[1, 1] + calib.K_right[1, 1]) * 0.5
    corners = np.array([[0.0, 0.0], [w - 1, 0.0], [0.0, h - 1], [w - 1, h - 1]])
    centres = []
    for K, D, Rk in cams:
        x, y = _turned(viewing_rays(K, D, corners, steps, model), Rk)
        centres.append(np.array([(w - 1) / 2 - f * x.mean(), (h - 1) / 2 - f * y.mean()]))
    cx, cy = (centres[0] + centres[1]) * 0.5
    s = -np.inf
    for K, D, Rk in cams:
        left, right, top, bottom = (_turned(viewing_rays(K, D, side, steps, model), Rk) for side in _border(w, h))
        ix0, ix1 = f * left[0].max() + cx, f * right[0].min() + cx
        iy0, iy1 = f * top[1].max() + cy, f * bottom[1].min() + cy
        s = max(s, cx / (cx - ix0), cy / (cy - iy0), (w - 1 - cx) / (ix1 - cx), (h - 1 - cy) / (iy1 - cy))
    return f * s, cx, cy


def _equidistant_view(calib: StereoCalibration, R1: np.ndarray, R2: np.ndarray,
                      fov_deg: float) -> tuple[float, float, float]:
    """Step 3 for equidistant: (f, cx, cy)."""
    w, h = calib.image_size
    cx, cy = (w - 1) / 2, (h - 1) / 2
    f = (w / 2) / np.tan(np.radians(fov_deg) / 2)
    for K, D, Rk in ((calib.K_left, calib.D_left, R1), (calib.K_right, calib.D_right, R2)):
        left, right, top, bottom = (_turned(viewing_rays(K, D, side, 0, "equidistant"), Rk) for side in _border(w, h))
        # inner extents (tangent units) of the border on each side of the rectified axis; a ray
        # behind the camera (NaN) or across the axis (a lens wider than 180° wraps) bounds nothing
        for half, extent in ((cx, -left[0]), (w - 1 - cx, right[0]), (cy, -top[1]), (h - 1 - cy, bottom[1])):
            with np.errstate(invalid="ignore"):
                extent = extent[extent > 0]
            if extent.size:
                f = max(f, half / float(extent.min()))
    return float(f), cx, cy


def stereo_rectify(calib: StereoCalibration, fov_deg: float = EQUIDISTANT_FOV_DEG) -> RectifiedGeometry:
    """Rectified geometry of a horizontal head (see the module docstring); ``fov_deg`` is the
    equidistant output field of view (the device's ``rectified_fov``; the other models ignore it)."""
    if not 0.0 < fov_deg < 180.0:
        raise ValueError(f"the rectified field of view must lie in (0, 180) degrees, got {fov_deg}")
    R1, R2, tx = _rotations(calib)
    if calib.lens_model == "equidistant":
        f, cx, cy = _equidistant_view(calib, R1, R2, fov_deg)
    else:
        f, cx, cy = _pinhole_view(calib, R1, R2)
    P1 = np.array([[f, 0.0, cx, 0.0], [0.0, f, cy, 0.0], [0.0, 0.0, 1.0, 0.0]])
    P2 = P1.copy()
    P2[0, 3] = tx * f
    Q = np.array([[1.0, 0.0, 0.0, -cx], [0.0, 1.0, 0.0, -cy], [0.0, 0.0, 0.0, f], [0.0, 0.0, -1.0 / tx, 0.0]])
    return RectifiedGeometry(calib.image_size, R1, R2, P1, P2, Q)


def rectified_to_raw(K: np.ndarray, D: np.ndarray, lens_model: str, R: np.ndarray, P: np.ndarray,
                     pts: np.ndarray) -> np.ndarray:
    """Step 5, the remap table at rectified pixels (N, 2): the raw pixel (N, 2) each one samples.

    ray = (P[:, :3]·R)⁻¹·(u, v, 1); pinhole models: x = ray_x/ray_z, y = ray_y/ray_z, then the lens's
    distortion (OpenCV's formulas) and K; equidistant: θ = atan2(√(ray_x² + ray_y²), ray_z),
    θ_d = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸), (x, y) = θ_d·(ray_x, ray_y)/√(ray_x² + ray_y²), then K.
    """
    ir = np.linalg.inv(np.asarray(P, np.float64)[:3, :3] @ np.asarray(R, np.float64))
    ray = np.column_stack([pts, np.ones(len(pts))]) @ ir.T
    d = np.zeros(8)
    coeffs = np.asarray(D, np.float64).ravel()
    d[:len(coeffs)] = coeffs
    if lens_model == "equidistant":
        r = np.hypot(ray[:, 0], ray[:, 1])
        theta = np.arctan2(r, ray[:, 2])
        t2 = theta * theta
        theta_d = theta * (1.0 + t2 * (d[0] + t2 * (d[1] + t2 * (d[2] + t2 * d[3]))))
        scale = np.where(r > 0, theta_d / np.maximum(r, 1e-300), 1.0 / ray[:, 2])
        x, y = ray[:, 0] * scale, ray[:, 1] * scale
    else:
        xn, yn = ray[:, 0] / ray[:, 2], ray[:, 1] / ray[:, 2]
        r2 = xn * xn + yn * yn
        kr = (1.0 + ((d[4] * r2 + d[1]) * r2 + d[0]) * r2) / (1.0 + ((d[7] * r2 + d[6]) * r2 + d[5]) * r2)
        x = xn * kr + 2.0 * d[2] * xn * yn + d[3] * (r2 + 2.0 * xn * xn)
        y = yn * kr + d[2] * (r2 + 2.0 * yn * yn) + 2.0 * d[3] * xn * yn
    return np.column_stack([K[0, 0] * x + K[0, 2], K[1, 1] * y + K[1, 2]])
