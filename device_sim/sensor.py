"""The sensor rig: two synchronised imagers on an ideal rectified stereo head, and their pixels.

Photometry: radiance (0..1) → signal in DN = radiance · 255 · (exposure / EXPOSURE_REF_US) · gain,
then shot noise (variance = signal / CONVERSION) and read noise (READ_NOISE_DN), quantised and
clipped to 8 bits. Both imagers expose at the same instant (one capture time for both).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from . import render, scene

SENSOR_W, SENSOR_H = 1280, 960
FOCAL_FULL_PX = 960.0  # 3.6 mm lens on 3.75 um pixels
BASELINE_M = 0.09
EXPOSURE_REF_US = 4000.0
CONVERSION = 4.0  # DN per sqrt(DN) of shot noise: variance = signal / CONVERSION
READ_NOISE_DN = 0.8
LIGHT = np.array([0.3, 0.45, 1.0]) / np.linalg.norm([0.3, 0.45, 1.0])  # travelling direction


@dataclass(frozen=True)
class Geometry:
    """Rectified pinhole geometry of the output images (what turns disparity into depth)."""

    width: int
    height: int
    focal_px: float
    cx: float
    cy: float
    baseline_m: float

    def rays(self) -> np.ndarray:
        """Camera-frame ray directions (x, y, 1) for every pixel centre, float32 (H, W, 3)."""
        xs = (np.arange(self.width) - self.cx) / self.focal_px
        ys = (np.arange(self.height) - self.cy) / self.focal_px
        r = np.ones((self.height, self.width, 3), np.float32)
        r[..., 0] = xs[None, :]
        r[..., 1] = ys[:, None]
        return r


def ideal_geometry(width: int, height: int) -> Geometry:
    """Binned/scaled output of the ideal head: square pixels, centred principal point."""
    f = FOCAL_FULL_PX * width / SENSOR_W
    return Geometry(width, height, f, (width - 1) / 2.0, (height - 1) / 2.0, BASELINE_M)


@nb.njit(cache=True, inline="always")
def _hash(k: np.uint64) -> np.uint64:
    """splitmix64 finaliser: a counter-based generator, reproducible per (frame, pixel)."""
    k ^= k >> np.uint64(30)
    k *= np.uint64(0xBF58476D1CE4E5B9)
    k ^= k >> np.uint64(27)
    k *= np.uint64(0x94D049BB133111EB)
    k ^= k >> np.uint64(31)
    return k


@nb.njit(cache=True, parallel=True, nogil=True)
def expose(radiance, scale, seed, out):
    """Radiance → 8-bit pixels with shot and read noise.

    The unit Gaussian is the Irwin–Hall sum of the four 16-bit quarters of one 64-bit hash
    (mean 2, variance 4/12), rescaled: no transcendental per pixel, tails cut at ±3.5 σ.
    """
    h, w = radiance.shape
    base = np.uint64(seed) * np.uint64(0x9E3779B97F4A7C15)
    m16 = np.uint64(0xFFFF)
    for y in nb.prange(h):
        for x in range(w):
            r = _hash(base + np.uint64(y * w + x))
            s4 = float(r & m16) + float((r >> np.uint64(16)) & m16) + float((r >> np.uint64(32)) & m16) \
                + float(r >> np.uint64(48))
            g = (s4 / 65536.0 - 2.0) * 1.7320508075688772
            s = radiance[y, x] * scale
            v = s + g * math.sqrt(READ_NOISE_DN * READ_NOISE_DN + max(s, 0.0) / CONVERSION)
            v = math.floor(v + 0.5)
            out[y, x] = 0 if v < 0 else (255 if v > 255 else np.uint8(v))


class SensorRig:
    """Renders both imagers of one unit; caches per-format ray tables and scratch buffers."""

    def __init__(self, seed: int = 0):
        self.seed = seed
        self.texture, self.tex_offsets = render.pack_pyramid(render.make_texture(seed))
        self.tex_side = 512
        self._format: tuple[int, int] | None = None
        self.geometry = ideal_geometry(640, 480)

    def set_format(self, width: int, height: int) -> None:
        if self._format == (width, height):
            return
        self.geometry = ideal_geometry(width, height)
        self._rays = self.geometry.rays()
        self._rad = np.empty((height, width), np.float32)
        self._format = (width, height)

    def capture(self, t: float, scene_id: int, exposure_us: int, gain: int, frame_seed: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Left, right (uint8) and the left camera's true depth in metres (float32, inf = none)."""
        g = self.geometry
        prims = scene.primitives(scene_id, t)
        scale = 255.0 * exposure_us / EXPOSURE_REF_US * 10.0 ** (gain / 200.0)
        depth = np.empty((g.height, g.width), np.float32)
        scratch = np.empty_like(depth)
        images = []
        for eye, origin in enumerate(((0.0, 0.0, 0.0), (g.baseline_m, 0.0, 0.0))):
            render.render_radiance(self._rays, np.array(origin), np.eye(3), prims, self.texture,
                                   self.tex_offsets, self.tex_side, LIGHT, self._rad,
                                   depth if eye == 0 else scratch)
            img = np.empty((g.height, g.width), np.uint8)
            expose(self._rad, scale, (frame_seed * 2 + eye) ^ (self.seed << 32), img)
            images.append(img)
        return images[0], images[1], depth
