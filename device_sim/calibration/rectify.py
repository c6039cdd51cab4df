"""On-board rectification, computed by the device from its stored calibration (no OpenCV here).

stereo_rectify (protocol/rectification.py, shared with the host) gives the geometry;
undistort_rectify_map() is cv2.initUndistortRectifyMap (float32 maps) for plumb_bob and
rational_polynomial lenses and cv2.fisheye.initUndistortRectifyMap for equidistant ones; remap_bilinear() is
cv2.remap(INTER_LINEAR, BORDER_CONSTANT 0) in double precision with rounding to nearest, as
OpenCV 5 computes it for float maps (OpenCV 4 quantised to 1/32 px; both agree to ±1 DN on
smooth images). What depends only on the maps (source pixel, weights, which pixels touch the
border) is worked out once per map (``RemapPlan``), so a frame costs four loads and a blend.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.rectification import EQUIDISTANT_FOV_DEG, RectifiedGeometry, stereo_rectify


INSIDE_NONE, INSIDE_BORDER = -1, -2  # RemapPlan.index: sampled at no raw pixel / partly outside


@dataclass(frozen=True)
class RemapPlan:
    """A float map prepared for raw images of ``source_shape``: per output pixel the flat index of
    its top-left source pixel when all four lie inside (else INSIDE_NONE or INSIDE_BORDER) and the
    bilinear weights, exactly as ``_remap`` computes them per pixel."""

    source_shape: tuple[int, int]
    map_x: np.ndarray
    map_y: np.ndarray
    index: np.ndarray
    ax: np.ndarray
    ay: np.ndarray

    @classmethod
    def of(cls, map_x: np.ndarray, map_y: np.ndarray, source_shape: tuple[int, int]) -> "RemapPlan":
        if map_x.shape != map_y.shape or map_x.dtype != np.float32 or map_y.dtype != np.float32:
            raise ValueError("map_x and map_y must be float32 arrays of the same shape")
        h, w = source_shape
        return cls((h, w), map_x, map_y, *_plan(map_x, map_y, w, h))

    def apply(self, img: np.ndarray) -> np.ndarray:
        """The remapped u8 image (see ``remap_bilinear``)."""
        if img.dtype != np.uint8 or img.shape != self.source_shape:
            raise ValueError(f"remap takes a {self.source_shape} uint8 image, got {img.dtype} {img.shape}")
        return _remap_planned(np.ascontiguousarray(img), self.index, self.ax, self.ay, self.map_x, self.map_y)


@dataclass(frozen=True)
class RectificationMaps:
    """Geometry plus per-camera float32 maps: rectified (u, v) → raw (map_x, map_y)."""

    geometry: RectifiedGeometry
    left_x: np.ndarray
    left_y: np.ndarray
    right_x: np.ndarray
    right_y: np.ndarray

    def __post_init__(self) -> None:
        shape = (self.geometry.image_size[1], self.geometry.image_size[0])  # raw images have the rectified format
        object.__setattr__(self, "_plans", (RemapPlan.of(self.left_x, self.left_y, shape),
                                            RemapPlan.of(self.right_x, self.right_y, shape)))

    def rectify(self, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rectify a raw u8 pair."""
        plan_l, plan_r = self._plans  # type: ignore[attr-defined]
        return plan_l.apply(left), plan_r.apply(right)


@numba.njit(parallel=True, nogil=True, cache=True)
def _map(ir: np.ndarray, fx: float, fy: float, u0: float, v0: float, d: np.ndarray, fisheye: bool,
         width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    mx = np.empty((height, width), dtype=np.float32)
    my = np.empty((height, width), dtype=np.float32)
    for i in numba.prange(height):
        for j in range(width):
            _x = i * ir[0, 1] + ir[0, 2] + j * ir[0, 0]
            _y = i * ir[1, 1] + ir[1, 2] + j * ir[1, 0]
            _w = i * ir[2, 1] + ir[2, 2] + j * ir[2, 0]
            if fisheye:  # equidistant: θ_d = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸), as cv2.fisheye
                r = np.sqrt(_x * _x + _y * _y)
                theta = np.arctan2(r, _w)
                t2 = theta * theta
                theta_d = theta * (1.0 + t2 * (d[0] + t2 * (d[1] + t2 * (d[2] + t2 * d[3]))))
                scale = theta_d / r if r > 0.0 else 1.0 / _w
                mx[i, j] = fx * _x * scale + u0
                my[i, j] = fy * _y * scale + v0
                continue
            w = 1.0 / _w if _w != 0.0 else np.inf
            x, y = _x * w, _y * w
            x2, y2 = x * x, y * y
            r2, _2xy = x2 + y2, 2.0 * x * y
            kr = (1.0 + ((d[4] * r2 + d[1]) * r2 + d[0]) * r2) / (1.0 + ((d[7] * r2 + d[6]) * r2 + d[5]) * r2)
            mx[i, j] = fx * (x * kr + d[2] * _2xy + d[3] * (r2 + 2.0 * x2)) + u0
            my[i, j] = fy * (y * kr + d[2] * (r2 + 2.0 * y2) + d[3] * _2xy) + v0
    return mx, my


def undistort_rectify_map(K: np.ndarray, D: np.ndarray, R: np.ndarray, P: np.ndarray,
                          size: tuple[int, int], lens_model: str = "plumb_bob") -> tuple[np.ndarray, np.ndarray]:
    """Float32 maps (H, W): for each rectified pixel, where to sample the raw image."""
    ir = np.linalg.inv(np.asarray(P, np.float64)[:3, :3] @ np.asarray(R, np.float64))
    d = np.zeros(8)
    coeffs = np.asarray(D, np.float64).ravel()
    d[:len(coeffs)] = coeffs
    return _map(ir, K[0, 0], K[1, 1], K[0, 2], K[1, 2], d, lens_model == "equidistant", size[0], size[1])


def rectification_maps(calib: StereoCalibration, fov_deg: float = EQUIDISTANT_FOV_DEG) -> RectificationMaps:
    """Geometry and remap tables for both cameras (``fov_deg``: an equidistant lens's rectified field of view)."""
    g = stereo_rectify(calib, fov_deg)
    lx, ly = undistort_rectify_map(calib.K_left, calib.D_left, g.R1, g.P1, g.image_size, calib.lens_model)
    rx, ry = undistort_rectify_map(calib.K_right, calib.D_right, g.R2, g.P2, g.image_size, calib.lens_model)
    return RectificationMaps(g, lx, ly, rx, ry)


@numba.njit(cache=True, inline="always")
def _sample_any(src: np.ndarray, x: float, y: float) -> int:
    """Bilinear sample at (x, y) with zeros outside, rounded to nearest (cv2.remap on float maps)."""
    h, w = src.shape
    x0, y0 = int(np.floor(x)), int(np.floor(y))
    if not (-1 <= x0 < w and -1 <= y0 < h):
        return 0
    ax, ay = x - x0, y - y0
    v00 = np.float64(src[y0, x0]) if 0 <= x0 and 0 <= y0 else 0.0
    v01 = np.float64(src[y0, x0 + 1]) if x0 + 1 < w and 0 <= y0 else 0.0
    v10 = np.float64(src[y0 + 1, x0]) if 0 <= x0 and y0 + 1 < h else 0.0
    v11 = np.float64(src[y0 + 1, x0 + 1]) if x0 + 1 < w and y0 + 1 < h else 0.0
    v = (1.0 - ay) * ((1.0 - ax) * v00 + ax * v01) + ay * ((1.0 - ax) * v10 + ax * v11)
    return min(255, int(np.rint(v)))


@numba.njit(parallel=True, nogil=True, cache=True)
def _plan(map_x: np.ndarray, map_y: np.ndarray, w: int, h: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    index = np.empty(map_x.shape, np.int32)
    ax = np.empty(map_x.shape, np.float64)
    ay = np.empty(map_x.shape, np.float64)
    for i in numba.prange(map_x.shape[0]):
        for j in range(map_x.shape[1]):
            x, y = np.float64(map_x[i, j]), np.float64(map_y[i, j])
            x0, y0 = int(np.floor(x)), int(np.floor(y))
            ax[i, j], ay[i, j] = x - x0, y - y0
            if 0 <= x0 < w - 1 and 0 <= y0 < h - 1:
                index[i, j] = y0 * w + x0
            elif -1 <= x0 < w and -1 <= y0 < h:
                index[i, j] = INSIDE_BORDER
            else:
                index[i, j] = INSIDE_NONE
    return index, ax, ay


@numba.njit(parallel=True, nogil=True, cache=True)
def _remap_planned(src: np.ndarray, index: np.ndarray, ax_: np.ndarray, ay_: np.ndarray, map_x: np.ndarray,
                   map_y: np.ndarray) -> np.ndarray:
    w = src.shape[1]
    flat = src.ravel()
    out = np.empty(index.shape, dtype=np.uint8)
    for i in numba.prange(index.shape[0]):
        for j in range(index.shape[1]):
            k = index[i, j]
            if k >= 0:
                ax, ay = ax_[i, j], ay_[i, j]
                v00, v01 = np.float64(flat[k]), np.float64(flat[k + 1])
                v10, v11 = np.float64(flat[k + w]), np.float64(flat[k + w + 1])
                v = (1.0 - ay) * ((1.0 - ax) * v00 + ax * v01) + ay * ((1.0 - ax) * v10 + ax * v11)
                out[i, j] = min(255, int(np.rint(v)))
            elif k == INSIDE_NONE:
                out[i, j] = 0
            else:
                out[i, j] = _sample_any(src, np.float64(map_x[i, j]), np.float64(map_y[i, j]))
    return out


def remap_bilinear(img: np.ndarray, map_x: np.ndarray, map_y: np.ndarray) -> np.ndarray:
    """Bilinear u8 remap: out[i, j] = img sampled at (map_x[i, j], map_y[i, j]); outside → 0."""
    if img.dtype != np.uint8 or img.ndim != 2:
        raise ValueError(f"remap_bilinear takes a 2-D uint8 image, got {img.dtype} {img.shape}")
    return RemapPlan.of(map_x, map_y, img.shape).apply(img)
