"""On-board rectification, computed by the device from its stored calibration (no OpenCV here).

stereo_rectify(calib) reproduces cv2.stereoRectify(K1, D1, K2, D2, size, R, T,
flags=CALIB_ZERO_DISPARITY, alpha=0) for a horizontal head:
  * each camera turns by half of R (r_r = rodrigues(−½·rodrigues⁻¹(R))), then both by the rotation
    that brings t = r_r·T onto the ±x axis: R1 = wR·r_rᵀ, R2 = wR·r_r;
  * focal f = mean of the two fy, then scaled so that only valid pixels remain (alpha = 0: the
    largest of the per-side ratios between the image half-extents and the inner rectangle of the
    undistorted, rotated image border sampled at 9 points per side);
  * principal point: the point that centres the undistorted image corners, averaged over both
    cameras (zero disparity: cx and cy are equal in P1 and P2, so Q[3][3] = 0 and Z = f·B/d).
    Points are undistorted with OpenCV's 5 fixed-point steps in these two places, as it does.
  * P1 = [f 0 cx 0; 0 f cy 0; 0 0 1 0], P2 = P1 with P2[0,3] = −f·B (B = baseline, metres);
    Q = [1 0 0 −cx; 0 1 0 −cy; 0 0 0 f; 0 0 1/B 0].
undistort_rectify_map() is cv2.initUndistortRectifyMap (float32 maps), remap_bilinear() is
cv2.remap(INTER_LINEAR, BORDER_CONSTANT 0) in double precision with rounding to nearest, as
OpenCV 5 computes it for float maps (OpenCV 4 quantised to 1/32 px; both agree to ±1 DN on
smooth images).
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from protocol.calibration import StereoCalibration
from .truth import rodrigues

_OPENCV_UNDISTORT_STEPS = 5


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


@dataclass(frozen=True)
class RectificationMaps:
    """Geometry plus per-camera float32 maps: rectified (u, v) → raw (map_x, map_y)."""

    geometry: RectifiedGeometry
    left_x: np.ndarray
    left_y: np.ndarray
    right_x: np.ndarray
    right_y: np.ndarray

    def rectify(self, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rectify a raw u8 pair."""
        return remap_bilinear(left, self.left_x, self.left_y), remap_bilinear(right, self.right_x, self.right_y)


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


def undistort_points(K: np.ndarray, D: np.ndarray, pts: np.ndarray, steps: int) -> np.ndarray:
    """Normalised undistorted coordinates (N, 2) of pixel points, `steps` fixed-point iterations."""
    k1, k2, p1, p2, k3 = D
    x0 = (pts[:, 0] - K[0, 2]) / K[0, 0]
    y0 = (pts[:, 1] - K[1, 2]) / K[1, 1]
    x, y = x0.copy(), y0.copy()
    for _ in range(steps):
        r2 = x * x + y * y
        icdist = 1.0 / (1.0 + ((k3 * r2 + k2) * r2 + k1) * r2)
        x, y = ((x0 - (2 * p1 * x * y + p2 * (r2 + 2 * x * x))) * icdist,
                (y0 - (p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)) * icdist)
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
    f = (calib.K_left[1, 1] + calib.K_right[1, 1]) * 0.5
    corners = np.array([[0.0, 0.0], [w - 1, 0.0], [0.0, h - 1], [w - 1, h - 1]])
    centres = [np.array([(w - 1) / 2, (h - 1) / 2]) -
               _project(undistort_points(K, D, corners, _OPENCV_UNDISTORT_STEPS), Rk, f, 0.0, 0.0).mean(axis=0)
               for K, D, Rk in cams]
    cx, cy = (centres[0] + centres[1]) * 0.5
    # alpha = 0: zoom until the inner rectangle of both undistorted image borders fills the frame
    # (as OpenCV 5 samples it: 9 points per side from pixel 0 to pixel w-1 / h-1, corners included)
    a = np.linspace(0.0, 1.0, 9)
    sides = [np.column_stack([np.zeros(9), a * (h - 1)]), np.column_stack([np.full(9, w - 1.0), a * (h - 1)]),
             np.column_stack([a * (w - 1), np.zeros(9)]), np.column_stack([a * (w - 1), np.full(9, h - 1.0)])]
    s = -np.inf
    for K, D, Rk in cams:
        left, right, top, bottom = (_project(undistort_points(K, D, side, _OPENCV_UNDISTORT_STEPS), Rk, f, cx, cy)
                                    for side in sides)
        ix0, ix1, iy0, iy1 = left[:, 0].max(), right[:, 0].min(), top[:, 1].max(), bottom[:, 1].min()
        s = max(s, cx / (cx - ix0), cy / (cy - iy0), (w - 1 - cx) / (ix1 - cx), (h - 1 - cy) / (iy1 - cy))
    f *= s
    P1 = np.array([[f, 0.0, cx, 0.0], [0.0, f, cy, 0.0], [0.0, 0.0, 1.0, 0.0]])
    P2 = P1.copy()
    P2[0, 3] = tx * f
    Q = np.array([[1.0, 0.0, 0.0, -cx], [0.0, 1.0, 0.0, -cy], [0.0, 0.0, 0.0, f], [0.0, 0.0, -1.0 / tx, 0.0]])
    return RectifiedGeometry((w, h), R1, R2, P1, P2, Q)


@numba.njit(parallel=True, nogil=True, cache=True)
def _map(ir: np.ndarray, fx: float, fy: float, u0: float, v0: float, d: np.ndarray,
         width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    k1, k2, p1, p2, k3 = d[0], d[1], d[2], d[3], d[4]
    mx = np.empty((height, width), dtype=np.float32)
    my = np.empty((height, width), dtype=np.float32)
    for i in numba.prange(height):
        for j in range(width):
            _x = i * ir[0, 1] + ir[0, 2] + j * ir[0, 0]
            _y = i * ir[1, 1] + ir[1, 2] + j * ir[1, 0]
            _w = i * ir[2, 1] + ir[2, 2] + j * ir[2, 0]
            w = 1.0 / _w if _w != 0.0 else np.inf
            x, y = _x * w, _y * w
            x2, y2 = x * x, y * y
            r2, _2xy = x2 + y2, 2.0 * x * y
            kr = 1.0 + ((k3 * r2 + k2) * r2 + k1) * r2
            mx[i, j] = fx * (x * kr + p1 * _2xy + p2 * (r2 + 2.0 * x2)) + u0
            my[i, j] = fy * (y * kr + p1 * (r2 + 2.0 * y2) + p2 * _2xy) + v0
    return mx, my


def undistort_rectify_map(K: np.ndarray, D: np.ndarray, R: np.ndarray, P: np.ndarray,
                          size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Float32 maps (H, W): for each rectified pixel, where to sample the raw image."""
    ir = np.linalg.inv(np.asarray(P, np.float64)[:3, :3] @ np.asarray(R, np.float64))
    return _map(ir, K[0, 0], K[1, 1], K[0, 2], K[1, 2], np.asarray(D, np.float64).reshape(5), size[0], size[1])


def rectification_maps(calib: StereoCalibration) -> RectificationMaps:
    """Geometry and remap tables for both cameras."""
    g = stereo_rectify(calib)
    lx, ly = undistort_rectify_map(calib.K_left, calib.D_left, g.R1, g.P1, g.image_size)
    rx, ry = undistort_rectify_map(calib.K_right, calib.D_right, g.R2, g.P2, g.image_size)
    return RectificationMaps(g, lx, ly, rx, ry)


@numba.njit(parallel=True, nogil=True, cache=True)
def _remap(src: np.ndarray, map_x: np.ndarray, map_y: np.ndarray) -> np.ndarray:
    h, w = src.shape
    out = np.empty(map_x.shape, dtype=np.uint8)
    for i in numba.prange(map_x.shape[0]):
        for j in range(map_x.shape[1]):
            x, y = np.float64(map_x[i, j]), np.float64(map_y[i, j])
            x0, y0 = int(np.floor(x)), int(np.floor(y))
            if not (-1 <= x0 < w and -1 <= y0 < h):
                out[i, j] = 0
                continue
            ax, ay = x - x0, y - y0
            v00 = np.float64(src[y0, x0]) if 0 <= x0 and 0 <= y0 else 0.0
            v01 = np.float64(src[y0, x0 + 1]) if x0 + 1 < w and 0 <= y0 else 0.0
            v10 = np.float64(src[y0 + 1, x0]) if 0 <= x0 and y0 + 1 < h else 0.0
            v11 = np.float64(src[y0 + 1, x0 + 1]) if x0 + 1 < w and y0 + 1 < h else 0.0
            v = (1.0 - ay) * ((1.0 - ax) * v00 + ax * v01) + ay * ((1.0 - ax) * v10 + ax * v11)
            out[i, j] = min(255, int(np.rint(v)))
    return out


def remap_bilinear(img: np.ndarray, map_x: np.ndarray, map_y: np.ndarray) -> np.ndarray:
    """Bilinear u8 remap: out[i, j] = img sampled at (map_x[i, j], map_y[i, j]); outside → 0."""
    if img.dtype != np.uint8 or img.ndim != 2:
        raise ValueError(f"remap_bilinear takes a 2-D uint8 image, got {img.dtype} {img.shape}")
    if map_x.shape != map_y.shape or map_x.dtype != np.float32 or map_y.dtype != np.float32:
        raise ValueError("map_x and map_y must be float32 arrays of the same shape")
    return _remap(np.ascontiguousarray(img), map_x, map_y)
