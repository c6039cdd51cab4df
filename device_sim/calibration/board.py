"""Chessboard calibration target in the simulator: varied poses and ray-cast rendering of raw views.
The board's geometry (BoardSpec, BoardPose, the board frame) is stereocam.stereo.calibration_board.

Anti-aliasing is analytic: each (sub-)pixel ray is intersected with the board plane and the
pattern is box-filtered over the sample's footprint on the board (an axis-aligned box in board
units, sized from the neighbouring rays' hits). The chessboard is separable (black where
s(u)·s(v) = +1 inside the squares, s the ±1 square wave), so the box integral is exact per axis
in closed form; the board's outline against the background is filtered the same way. Edges land
where they should to ~1e-3 px already at supersample=1.
"""
from __future__ import annotations

from collections.abc import Iterator

import numba
import numpy as np

from stereocam.stereo.calibration_board import BoardPose, BoardSpec
from stereocam.protocol.calibration import StereoCalibration
from .rays import lens_project, lens_rays
from stereocam.protocol.rectification import rodrigues, viewing_rays


@numba.njit(inline="always")
def _square_wave_integral(t: float) -> float:
    """∫_0^t of the period-2 square wave that is +1 on [0, 1) and −1 on [1, 2)."""
    m = t - 2.0 * np.floor(t / 2.0)
    return 1.0 - abs(m - 1.0)


@numba.njit(inline="always")
def _box_terms(t: float, width: float, n: float) -> tuple[float, float]:
    """Box filter of `width` at t over [0, n) (units: squares): (mean of 1, mean of square wave)."""
    if width < 1e-6:
        if 0.0 <= t < n:
            return 1.0, 1.0 if (int(np.floor(t)) & 1) == 0 else -1.0
        return 0.0, 0.0
    lo, hi = max(t - 0.5 * width, 0.0), min(t + 0.5 * width, n)
    if hi <= lo:
        return 0.0, 0.0
    return (hi - lo) / width, (_square_wave_integral(hi) - _square_wave_integral(lo)) / width


@numba.njit(inline="always")
def _hit(d: np.ndarray, R: np.ndarray, t: np.ndarray, nt: float) -> tuple[float, float, bool]:
    """Board-plane coordinates (u, v) where ray d meets the board; False if it does not."""
    den = R[0, 2] * d[0] + R[1, 2] * d[1] + R[2, 2] * d[2]
    lam = nt / den if den != 0.0 else -1.0
    if lam <= 0.0:
        return 0.0, 0.0, False
    px, py, pz = lam * d[0] - t[0], lam * d[1] - t[1], lam * d[2] - t[2]
    return (R[0, 0] * px + R[1, 0] * py + R[2, 0] * pz, R[0, 1] * px + R[1, 1] * py + R[2, 1] * pz, True)


@numba.njit(parallel=True, nogil=True, cache=True)
def _render(rays: np.ndarray, R: np.ndarray, t: np.ndarray, cols: int, rows: int, sq: float,
            margin: float, s: int, black: float, white: float, background: float) -> np.ndarray:
    hs, ws = rays.shape[0], rays.shape[1]
    nt = R[0, 2] * t[0] + R[1, 2] * t[1] + R[2, 2] * t[2]
    lo, hx, hy = -sq - margin, cols * sq + margin, rows * sq + margin
    out = np.empty((hs // s, ws // s), dtype=np.float32)
    for j in numba.prange(hs // s):
        for i in range(ws // s):
            acc = 0.0
            for a in range(s):
                for b in range(s):
                    y, x = j * s + a, i * s + b
                    u, v, ok = _hit(rays[y, x], R, t, nt)
                    if not ok or u < lo - sq or u >= hx + sq or v < lo - sq or v >= hy + sq:
                        acc += background
                    else:
                        # footprint of this sample on the board, from its neighbours' hits
                        ux, vx, okx = _hit(rays[y, x + 1 if x + 1 < ws else x - 1], R, t, nt)
                        uy, vy, oky = _hit(rays[y + 1 if y + 1 < hs else y - 1, x], R, t, nt)
                        wu = (abs(ux - u) + abs(uy - u)) / sq if okx and oky else 0.0
                        wv = (abs(vx - v) + abs(vy - v)) / sq if okx and oky else 0.0
                        # black = inside the squares and s(u)·s(v) = +1: a separable box integral
                        au, bu = _box_terms(u / sq + 1.0, wu, cols + 1.0)
                        av, bv = _box_terms(v / sq + 1.0, wv, rows + 1.0)
                        mu, _ = _box_terms((u - lo) / sq, wu, (hx - lo) / sq)  # board incl. margin
                        mv, _ = _box_terms((v - lo) / sq, wv, (hy - lo) / sq)
                        acc += (background + (white - background) * mu * mv
                                - (white - black) * 0.5 * (au * av + bu * bv))
            out[j, i] = acc / (s * s)
    return out


def render_board_view(rays: np.ndarray, R_board: np.ndarray, t_board: np.ndarray, board: BoardSpec,
                      supersample: int = 1, noise_sigma: float = 1.0, rng: np.random.Generator | None = None,
                      black: float = 30.0, white: float = 220.0, background: float = 110.0) -> np.ndarray:
    """Raw u8 view of the board at pose (R_board, t_board) in this camera's frame.

    `rays` come from pixel_rays(..., supersample=supersample): each output pixel is the box-filtered
    mean of its s×s sub-pixel samples, then Gaussian noise of `noise_sigma` DN is added.
    """
    if rays.ndim != 3 or rays.shape[2] != 3 or rays.shape[0] % supersample or rays.shape[1] % supersample:
        raise ValueError(f"rays of shape {rays.shape} do not fit supersample {supersample}")
    img = _render(rays, np.asarray(R_board, np.float64), np.asarray(t_board, np.float64).reshape(3),
                  board.cols, board.rows, board.square_m, board.margin_squares * board.square_m,
                  supersample, black, white, background)
    if noise_sigma > 0:
        img += (rng or np.random.default_rng()).normal(0.0, noise_sigma, img.shape).astype(np.float32)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _visible(calib: StereoCalibration, pose: BoardPose, board: BoardSpec, border_px: float) -> bool:
    w, h = calib.image_size
    outline = board.outline() @ pose.R.T + pose.t
    for K, D, pts in ((calib.K_left, calib.D_left, outline),
                      (calib.K_right, calib.D_right, outline @ calib.R.T + calib.T)):
        if np.any(pts[:, 2] <= 0.05):
            return False
        uv = lens_project(K, D, calib.lens_model, pts)
        if np.any(uv < border_px) or np.any(uv[:, 0] > w - 1 - border_px) or np.any(uv[:, 1] > h - 1 - border_px):
            return False
    return True


def board_poses(seed: int, n: int, board: BoardSpec, calib: StereoCalibration,
                distance_m: tuple[float, float] = (0.4, 1.5), max_tilt_deg: float = 40.0,
                max_roll_deg: float = 20.0, border_px: float = 4.0) -> Iterator[BoardPose]:
    """n varied poses, reproducible from the seed, with the whole board inside both images.

    Each pose: board centre at a uniform image position of the left camera at a distance drawn
    from `distance_m` (plumb_bob: depth along the axis through K⁻¹; other lens models: along the
    pixel's true viewing ray, so poses reach the whole field of a wide lens), tilted by up to
    `max_tilt_deg` about a random in-plane axis and rolled by up to `max_roll_deg`. Poses where
    the board would leave either image are redrawn.
    """
    rng = np.random.default_rng([0xB0A2D, int(seed)])
    w, h = calib.image_size
    centre = np.array([(board.cols - 1) / 2, (board.rows - 1) / 2, 0.0]) * board.square_m
    K_inv = np.linalg.inv(calib.K_left)
    made = 0
    for _ in range(2000 * max(n, 1)):
        if made == n:
            return
        z = rng.uniform(*distance_m)
        pixel = np.array([rng.uniform(0, w - 1), rng.uniform(0, h - 1), 1.0])
        phi = rng.uniform(0, 2 * np.pi)
        tilt = np.deg2rad(rng.uniform(0, max_tilt_deg)) * np.array([np.cos(phi), np.sin(phi), 0.0])
        roll = np.deg2rad(rng.uniform(-max_roll_deg, max_roll_deg))
        R = rodrigues(tilt) @ rodrigues(np.array([0.0, 0.0, roll]))
        if calib.lens_model == "plumb_bob":
            ray = K_inv @ pixel
        else:
            ray = viewing_rays(calib.K_left, calib.D_left, pixel[None, :2], 200, calib.lens_model)[0]
            ray = ray / np.linalg.norm(ray)
        pose = BoardPose(R, z * ray - R @ centre)
        if _visible(calib, pose, board, border_px):
            made += 1
            yield pose
    raise ValueError(f"board {board.cols}x{board.rows} x {board.square_m} m does not fit the "
                     f"{w}x{h} view at {distance_m} m often enough")


class StereoBoardRenderer:
    """Renders raw (left, right) views of a board through a stereo head's true calibration."""

    def __init__(self, calib: StereoCalibration, board: BoardSpec, supersample: int = 1) -> None:
        w, h = calib.image_size
        self.calib, self.board, self.supersample = calib, board, supersample
        self._rays = [lens_rays(K, D, calib.lens_model, w, h, supersample)
                      for K, D in ((calib.K_left, calib.D_left), (calib.K_right, calib.D_right))]

    def render(self, pose: BoardPose, rng: np.random.Generator | None = None,
               noise_sigma: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """(left, right) u8 views of the board at `pose` (given in the left camera frame)."""
        right_R, right_t = self.calib.R @ pose.R, self.calib.R @ pose.t + self.calib.T
        return (render_board_view(self._rays[0], pose.R, pose.t, self.board, self.supersample, noise_sigma, rng),
                render_board_view(self._rays[1], right_R, right_t, self.board, self.supersample, noise_sigma, rng))
