"""Synthetic stereo board views through any lens model, with known truth (the calibration tool's
tests and `stereocam bench calib-synthetic`).

A board is drawn flat (a texture, plus the affine map from board metres to texture pixels), then
every pixel of each camera is traced back through the camera's lens model (rational / plumb_bob:
cv2.undistortPoints iterated to convergence; equidistant: Newton on theta_d = theta(1 + k1 theta^2 + ...),
so rays beyond 90 degrees of a 190-degree lens are exact) to its viewing ray, intersected with the
board plane and sampled from the texture (cv2.remap through the inverse map). Boards:

  chessboard  cols x rows inner corners (square ones included), corner squares black, 1-square margin
  charuco     cv2.aruco CharucoBoard.generateImage, legacy or current layout, normal or inverted
  aprilgrid   Kalibr's layout: tag36h11 tags (DICT_APRILTAG_36h11, 2-bit border), tag 0 bottom-left,
              black squares of spacing x tag in the gaps at every tag corner
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from stereocam.protocol.calibration import StereoCalibration

PX = 48  # texture pixels per square (per tag)


@dataclass(frozen=True)
class Texture:
    """A flat board image and the map board (x, y) metres -> texture pixel (u, v) = A @ (x, y, 1)
    (pixel centres at integer (u, v), as cv2.remap samples)."""

    image: np.ndarray
    A: np.ndarray
    outline: np.ndarray  # (4, 2) board metres: the printed area (poses keep it in view)


def chessboard(cols: int, rows: int, square: float) -> Texture:
    """Inner corner (i, j) at (i, j)·square, as BoardSpec.object_points numbers them."""
    n_x, n_y = cols + 1, rows + 1
    img = np.full(((n_y + 2) * PX, (n_x + 2) * PX), 255, np.uint8)
    for b in range(n_y):
        for a in range(n_x):
            if (a + b) % 2 == 0:
                img[(b + 1) * PX:(b + 2) * PX, (a + 1) * PX:(a + 2) * PX] = 0
    A = np.array([[PX / square, 0, 2 * PX - 0.5], [0, PX / square, 2 * PX - 0.5]])
    lo, hx, hy = -2 * square, (cols + 1) * square, (rows + 1) * square
    return Texture(img, A, np.array([[lo, lo], [hx, lo], [hx, hy], [lo, hy]]))


def charuco(cols: int, rows: int, square: float, marker: float, dictionary: str, legacy: bool,
            inverted: bool = False) -> Texture:
    """OpenCV's own drawing; board (x, y) as getChessboardCorners gives them; inverted: white on black."""
    board = cv2.aruco.CharucoBoard((cols, rows), square, marker,
                                   cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)))
    board.setLegacyPattern(legacy)
    img = board.generateImage((cols * PX, rows * PX), marginSize=0, borderBits=1)
    if inverted:
        img = 255 - img
    img = cv2.copyMakeBorder(img, PX, PX, PX, PX, cv2.BORDER_CONSTANT, value=255)
    A = np.array([[PX / square, 0, PX - 0.5], [0, PX / square, PX - 0.5]])
    return Texture(img, A, np.array([[0, 0], [cols * square, 0], [cols * square, rows * square], [0, rows * square]]))


def aprilgrid(cols: int, rows: int, tag: float, spacing: float) -> Texture:
    """Kalibr's AprilGrid: Kalibr's board frame (origin at tag 0's bottom-left corner, y up the board)."""
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    T = 60  # tag36h11 with a 2-bit border is 10 bits wide
    gap = int(round(spacing * T))
    pitch = T + gap
    margin = gap + T // 2
    width, height = cols * pitch - gap, rows * pitch - gap
    img = np.full((height + 2 * margin, width + 2 * margin), 255, np.uint8)
    for r in range(rows):
        for c in range(cols):
            y0 = margin + (rows - 1 - r) * pitch
            img[y0:y0 + T, margin + c * pitch:margin + c * pitch + T] = cv2.aruco.generateImageMarker(
                dictionary, r * cols + c, T, borderBits=2)
    for r in range(rows + 1):
        for c in range(cols + 1):
            y, x = margin + r * pitch - gap, margin + c * pitch - gap
            img[y:y + gap, x:x + gap] = 0
    s = T / tag
    A = np.array([[s, 0, margin - 0.5], [0, -s, margin + height - 0.5]])
    w_m, h_m = width / s, height / s
    lo = -margin / s + 1e-4
    return Texture(img, A, np.array([[lo, lo], [w_m - lo, lo], [w_m - lo, h_m - lo], [lo, h_m - lo]]))


@dataclass(frozen=True)
class Camera:
    model: str
    K: np.ndarray
    D: np.ndarray
    size: tuple[int, int]

    def rays(self) -> np.ndarray:
        """Unit viewing ray of every pixel centre, (H, W, 3)."""
        w, h = self.size
        u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        if self.model == "equidistant":
            x, y = (u - self.K[0, 2]) / self.K[0, 0], (v - self.K[1, 2]) / self.K[1, 1]
            theta_d = np.hypot(x, y)
            theta = theta_d.copy()
            k = self.D
            for _ in range(60):
                t2 = theta * theta
                f = theta * (1 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3])))) - theta_d
                df = 1 + t2 * (3 * k[0] + t2 * (5 * k[1] + t2 * (7 * k[2] + t2 * 9 * k[3])))
                theta = np.clip(theta - f / df, 0.0, np.pi)
            phi = np.arctan2(y, x)
            return np.dstack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
        pts = np.dstack([u, v]).reshape(-1, 1, 2)
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
        n = cv2.undistortPoints(pts, self.K, self.D, R=None, P=None, criteria=crit).reshape(h, w, 2)
        d = np.dstack([n, np.ones((h, w))])
        return d / np.linalg.norm(d, axis=2, keepdims=True)

    def project(self, pts: np.ndarray) -> np.ndarray:
        """Camera-frame points (N, 3) to pixels (N, 2)."""
        p = np.asarray(pts, np.float64).reshape(-1, 1, 3)
        if self.model == "equidistant":
            return cv2.fisheye.projectPoints(p, np.zeros((3, 1)), np.zeros((3, 1)), self.K, self.D)[0].reshape(-1, 2)
        return cv2.projectPoints(p, np.zeros(3), np.zeros(3), self.K, self.D)[0].reshape(-1, 2)


def render(cam: Camera, rays: np.ndarray, tex: Texture, R: np.ndarray, t: np.ndarray, rng: np.random.Generator,
           background: int = 110, noise: float = 1.5) -> np.ndarray:
    """The board seen by `cam` in pose X_cam = R X_board + t, u8."""
    d = rays @ R  # rays in the board frame (R^T d)
    o = -R.T @ t
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = -o[2] / d[..., 2]
    hit = o[:2] + lam[..., None] * d[..., :2]
    uv = hit @ tex.A[:, :2].T + tex.A[:, 2]
    ok = np.isfinite(lam) & (lam > 0)
    mx = np.where(ok, uv[..., 0], -1e6).astype(np.float32)
    my = np.where(ok, uv[..., 1], -1e6).astype(np.float32)
    smooth = cv2.GaussianBlur(tex.image, (0, 0), 0.8)
    img = cv2.remap(smooth, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=background)
    img = cv2.GaussianBlur(img.astype(np.float32), (0, 0), 0.6) + rng.normal(0, noise, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


@dataclass(frozen=True)
class Rig:
    """A stereo head with known truth: X_right = R X_left + T."""

    left: Camera
    right: Camera
    R: np.ndarray
    T: np.ndarray

    def truth(self) -> StereoCalibration:
        return StereoCalibration(self.left.size, self.left.K, self.left.D, self.right.K, self.right.D, self.R,
                                 self.T, self.left.model)


def rig(model: str, fov_deg: float, size: tuple[int, int], baseline: float = 0.08) -> Rig:
    """A head whose lens spans `fov_deg` across the image width (D typical of the model)."""
    w, h = size
    half = np.radians(fov_deg) / 2
    if model == "equidistant":
        D = np.array([0.03, -0.01, 0.004, -0.001])
        f = (w / 2) / (half * (1 + D[0] * half ** 2 + D[1] * half ** 4 + D[2] * half ** 6 + D[3] * half ** 8))
    elif model == "rational_polynomial":
        # a wide-angle barrel lens that a 5-coefficient fit misses by px already at 3/4 of the field
        D = np.array([2.121, 0.723, 0.0003, -0.0002, 0.098, 0.983, 1.798, 0.025])
        r2 = np.tan(half) ** 2
        f = (w / 2) / (np.tan(half) * (1 + D[0] * r2 + D[1] * r2 ** 2 + D[4] * r2 ** 3)
                       / (1 + D[5] * r2 + D[6] * r2 ** 2 + D[7] * r2 ** 3))
    else:
        D = np.array([-0.12, 0.05, 0.0004, -0.0003, 0.0])
        f = (w / 2) / np.tan(half)
    K1 = np.array([[f, 0, w / 2 + 3.5], [0, f * 1.002, h / 2 - 2.5], [0, 0, 1]])
    K2 = np.array([[f * 1.004, 0, w / 2 - 4.0], [0, f * 1.006, h / 2 + 1.5], [0, 0, 1]])
    D2 = D * 1.03
    R = cv2.Rodrigues(np.array([0.004, -0.012, 0.003]))[0]
    T = np.array([-baseline, 0.0008, 0.0006])
    return Rig(Camera(model, K1, D, size), Camera(model, K2, D2, size), R, T)


def board_poses(head: Rig, tex: Texture, n: int, seed: int, distance: tuple[float, float],
                reach: float = 0.8, roll: float = 0.5, border: float = 8.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """n poses (R, t) of the board in the left camera with the whole printed area inside both images,
    spread over the field of view (up to `reach` of the half-width angle), tilted up to 40 degrees."""
    rng = np.random.default_rng(seed)
    out: list[tuple[np.ndarray, np.ndarray]] = []
    corners = np.column_stack([tex.outline, np.zeros(4)])
    # points along the outline's edges, so a bent edge through a strong lens is kept in view too
    edge = np.concatenate([corners[i] + np.linspace(0, 1, 12)[:, None] * (corners[(i + 1) % 4] - corners[i])
                           for i in range(4)])
    centre = corners.mean(axis=0)
    w, h = head.left.size
    half_fov = float(np.arctan2(w / 2, head.left.K[0, 0])) if head.left.model != "equidistant" \
        else (w / 2) / head.left.K[0, 0]
    for _ in range(20000):
        if len(out) == n:
            break
        ang = rng.uniform(0, reach) * min(half_fov, 1.5)
        phi = rng.uniform(-np.pi, np.pi)
        direction = np.array([np.sin(ang) * np.cos(phi), np.sin(ang) * np.sin(phi) * h / w, np.cos(ang)])
        direction /= np.linalg.norm(direction)
        # printed face towards the camera (board z along the line of sight), then tilt and roll
        z = direction
        x = np.cross([0.0, 1.0, 0.0], z)
        x /= np.linalg.norm(x)
        facing = np.column_stack([x, np.cross(z, x), z])  # board axes in the camera frame
        tilt = cv2.Rodrigues(np.array([rng.uniform(-0.7, 0.7), rng.uniform(-0.7, 0.7), rng.uniform(-roll, roll)]))[0]
        R = facing @ tilt
        if np.linalg.det(tex.A[:, :2]) < 0:  # a y-up board frame (Kalibr's): its +z faces the camera
            R = R @ np.diag([1.0, -1.0, -1.0])
        t = direction * rng.uniform(*distance) - R @ centre
        pl = edge @ R.T + t
        pr = pl @ head.R.T + head.T
        if pl[:, 2].min() <= 0.02 or pr[:, 2].min() <= 0.02:
            continue
        ul, ur = head.left.project(pl), head.right.project(pr)
        if all(np.all(np.isfinite(p)) and p[:, 0].min() > border and p[:, 1].min() > border
               and p[:, 0].max() < w - 1 - border and p[:, 1].max() < h - 1 - border for p in (ul, ur)):
            out.append((R, t))
    if len(out) < n:
        raise RuntimeError(f"only {len(out)} of {n} board poses fit in both views")
    return out


def stereo_views(head: Rig, tex: Texture, n: int, seed: int = 0, distance: tuple[float, float] = (0.4, 0.9),
                 late: tuple[int, ...] = (), free_running: bool = False, **pose_options: float
                 ) -> list[tuple[np.ndarray, np.ndarray]]:
    """n (left, right) u8 images of the board; in the pairs `late` the right frame sees the board
    moved 3 mm and 0.4 degrees on, obliquely (a pair whose frames are not from the same instant);
    free_running: in every pair, by 3.5 mm and 0.4 degrees in a random direction (free-running cameras)."""
    rng = np.random.default_rng(seed + 1000)
    rays_l, rays_r = head.left.rays(), head.right.rays()
    moved = cv2.Rodrigues(np.array([0.005, 0.005, 0.0]))[0]
    pairs = []
    for k, (R, t) in enumerate(board_poses(head, tex, n, seed, distance, **pose_options)):
        Rr, tr = head.R @ R, head.R @ t + head.T
        if free_running:
            axis, shift = rng.normal(size=3), rng.normal(size=3)
            Rr = Rr @ cv2.Rodrigues(0.007 * axis / np.linalg.norm(axis))[0]
            tr = tr + head.R @ (0.0035 * shift / np.linalg.norm(shift))
        elif k in late:
            Rr, tr = Rr @ moved, tr + head.R @ np.array([0.002, 0.002, 0.001])
        pairs.append((render(head.left, rays_l, tex, R, t, rng), render(head.right, rays_r, tex, Rr, tr, rng)))
    return pairs
