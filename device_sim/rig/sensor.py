"""The sensor rig: two synchronised imagers behind real lenses, and their pixels.

Photometry: radiance (0..1) → signal in DN = radiance · 255 · (exposure / EXPOSURE_REF_US) · gain,
then shot noise (variance = signal / CONVERSION) and read noise (READ_NOISE_DN), quantised and
clipped to 8 bits. Both imagers expose at the same instant (one capture time for both).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from . import render, scene, texture
from stereocam.stereo.calibration_board import BoardPose, BoardSpec
from ..calibration.board import StereoBoardRenderer, board_poses
from stereocam.protocol.calibration import StereoCalibration
from ..calibration.rays import lens_rays

SENSOR_W, SENSOR_H = 1280, 960
EXPOSURE_REF_US = 4000.0
CONVERSION = 4.0  # DN per sqrt(DN) of shot noise: variance = signal / CONVERSION
READ_NOISE_DN = 0.8
LIGHT = np.array([0.3, 0.45, 1.0]) / np.linalg.norm([0.3, 0.45, 1.0])  # travelling direction
BOARD = BoardSpec(cols=9, rows=6, square_m=0.03)  # the calibration scene's chessboard
BOARD_POSES = 120
BOARD_DWELL_S = 0.15  # a fixture robot: it holds each pose this long, then moves on


@dataclass(frozen=True)
class Geometry:
    """A rectified pinhole view (what turns disparity into depth): Z = f * B / d."""

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


@dataclass(frozen=True)
class _StaticLayer:
    """Per-pixel nearest hit and radiance of a scene's static primitives in one eye."""

    key: bytes  # the static primitives' values it was rendered from
    rad: np.ndarray
    t: np.ndarray
    hit: np.ndarray


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
def expose(radiance, scale, seed, out, noise=1.0):
    """Radiance → 8-bit pixels with shot and read noise (both times ``noise``).

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
            v = s + g * noise * math.sqrt(READ_NOISE_DN * READ_NOISE_DN + max(s, 0.0) / CONVERSION)
            v = math.floor(v + 0.5)
            out[y, x] = 0 if v < 0 else (255 if v > 255 else np.uint8(v))


class SensorRig:
    """Both imagers of one unit, seen through its true lenses (distortion, misalignment).

    The world frame is the left imager's frame; the right imager sits at -Rᵀ·T looking along Rᵀ
    (R, T as cv2.stereoCalibrate defines them). Images come out raw: distorted, unrectified.
    """

    def __init__(self, seed: int, truth: StereoCalibration, board_distance_m: tuple[float, float] = (0.45, 1.2)):
        """``board_distance_m``: how far the board fixture holds the board (rig/lens.py, per lens class)."""
        self.seed = seed
        self.truth = truth
        self.board_distance_m = board_distance_m
        self.texture, self.tex_offsets = texture.pack_pyramid(texture.make_texture(seed))
        self.tex_side = 512
        self._format: tuple[int, int] | None = None
        self._board: StereoBoardRenderer | None = None
        self._board_poses: list[BoardPose] = []
        self._layers: dict[tuple[int, scene.Scene], _StaticLayer] = {}

    def set_format(self, width: int, height: int) -> None:
        if self._format == (width, height):
            return
        cal = self.truth.scaled(width, height)
        self.calibration = cal
        self._rays = [lens_rays(cal.K_left, cal.D_left, cal.lens_model, width, height),
                      lens_rays(cal.K_right, cal.D_right, cal.lens_model, width, height)]
        self._cones = [render.ray_cones(r) for r in self._rays]
        self._poses = [(np.zeros(3), np.eye(3)), (self.right_centre, cal.R.T)]
        self._board = None
        self._layers = {}
        self._format = (width, height)

    @property
    def left_rays(self) -> np.ndarray:
        """Camera-frame rays of the left imager's raw pixels at the current format (through its lens)."""
        return self._rays[0]

    @property
    def right_centre(self) -> np.ndarray:
        """The right imager's centre in the world (left imager's) frame, metres."""
        return -self.truth.R.T @ self.truth.T.ravel()

    def _board_view(self, t: float, frame_seed: int) -> tuple[np.ndarray, np.ndarray]:
        if self._board is None:
            self._board = StereoBoardRenderer(self.calibration, BOARD)
            self._board_poses = list(board_poses(self.seed, BOARD_POSES, BOARD, self.calibration,
                                                 distance_m=self.board_distance_m))
        pose = self._board_poses[int(t / BOARD_DWELL_S) % len(self._board_poses)]
        return self._board.render(pose, np.random.default_rng(frame_seed))

    def capture(self, t: float, view: scene.Scene, exposure_us: int, gain: int, frame_seed: int
                ) -> tuple[np.ndarray, np.ndarray]:
        """Raw left and right images (uint8) exposed at the same instant ``t``."""
        if view == scene.Scene.BOARD:
            return self._board_view(t, frame_seed)
        moving = scene.moving_primitives(view)
        photo = scene.photometry(view)
        scale = 255.0 * exposure_us / EXPOSURE_REF_US * 10.0 ** (gain / 200.0)
        tables = [scene.primitives(view, ti) for ti in photo.instants(t)]  # blur: the path over the exposure
        images = []
        for eye in range(2):
            origin, rot = self._pose(eye, view)
            rad = np.zeros(self._rays[eye].shape[:2], np.float32)
            for prims in tables:
                layer = self._static_layer(eye, view, prims, moving)
                sub = np.empty(layer.rad.shape, np.float32)
                render.render_over(self._rays[eye], self._cones[eye], origin, rot, prims, moving, layer.rad,
                                   layer.t, layer.hit, self.texture, self.tex_offsets, self.tex_side, LIGHT, sub)
                rad += sub
            rad = photo.apply(rad / np.float32(len(tables)), self._rays[eye], eye)
            img = np.empty(rad.shape, np.uint8)
            expose(rad, scale, (frame_seed * 2 + eye) ^ (self.seed << 32), img, photo.noise)
            images.append(img)
        return images[0], images[1]

    def _pose(self, eye: int, view: scene.Scene) -> tuple[np.ndarray, np.ndarray]:
        """Eye's centre and camera -> world rotation looking at ``view``: the right eye turned off
        the pose its calibration holds in a misaligned scene class (a unit whose calibration drifted)."""
        origin, rot = self._poses[eye]
        turn = scene.right_turn(view)
        if eye == 1 and not np.array_equal(turn, np.eye(3)):
            rot = np.ascontiguousarray(rot @ turn)
        return origin, rot

    def _static_layer(self, eye: int, view: scene.Scene, prims: np.ndarray, moving: np.ndarray) -> _StaticLayer:
        """One eye's view of the scene's static primitives, rendered once per format (again only if
        they changed: the key is their exact values)."""
        static = np.setdiff1d(np.arange(prims.shape[0]), moving)
        key = prims[static].tobytes()
        layer = self._layers.get((eye, view))
        if layer is None or layer.key != key:
            h, w = self._rays[eye].shape[:2]
            layer = _StaticLayer(key, np.empty((h, w), np.float32), np.empty((h, w)), np.empty((h, w), np.int64))
            origin, rot = self._pose(eye, view)
            render.render_layer(self._rays[eye], origin, rot, prims, static, self.texture, self.tex_offsets,
                                self.tex_side, LIGHT, layer.rad, layer.t, layer.hit)
            self._layers[(eye, view)] = layer
        return layer

    def depth(self, t: float, view: scene.Scene, rays: np.ndarray, rot: np.ndarray) -> np.ndarray:
        """True depth (m, inf = nothing) along the optical axis of a view from the left imager's
        centre with camera-frame ``rays`` and camera→world rotation ``rot``."""
        if view == scene.Scene.BOARD:
            raise ValueError("no depth truth for the calibration scene")
        rad = np.empty(rays.shape[:2], np.float32)
        depth = np.empty_like(rad)
        render.render_radiance(rays, np.zeros(3), np.ascontiguousarray(rot, np.float64), scene.primitives(view, t),
                               self.texture, self.tex_offsets, self.tex_side, LIGHT, rad, depth)
        return depth
