"""The point cloud as the page's 3-D view and the Rerun bridge take it: every ``step``-th pixel's
3-D point (metres, left camera frame) with a colour, by depth (the disparity colour map) or by the
left image."""
from __future__ import annotations

import struct

import cv2
import numpy as np

import stereocam

COLOURINGS = ("depth", "left")


def sampled_points(frame: stereocam.Frame, step: int, colour: str,
                   span: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """(N x 3 float32 points, N x 3 uint8 RGB) of the valid pixels on a ``step`` grid; ``span``:
    the disparities (px) at the colour map's ends. ValueError for an unknown colouring or step,
    MissingPlaneError for a frame without disparity."""
    if colour not in COLOURINGS:
        raise ValueError(f"colour must be one of {', '.join(COLOURINGS)}, got {colour!r}")
    if not 1 <= step <= 64:
        raise ValueError(f"step must be 1..64, got {step}")
    if frame.disparity is None:
        raise stereocam.MissingPlaneError("this frame carries no disparity: no point cloud")
    raw = frame.disparity[::step, ::step]  # only the sampled pixels are converted
    fmt = frame.disparity_format
    ys, xs = np.nonzero((raw > 0) & (raw != fmt.invalid))
    dd = raw[ys, xs].astype(np.float32) / fmt.subpixel
    g = frame.geometry
    z = g.focal_px * g.baseline_m / dd
    u, v = xs * step, ys * step
    pts = np.stack([(u - g.cx) * z / g.focal_px, (v - g.cy) * z / g.focal_px, z], axis=1).astype(np.float32)
    if colour == "left" and frame.left is not None:
        grey = frame.left[v, u]
        rgb = np.repeat(grey[:, None], 3, axis=1).astype(np.uint8)
    else:
        lo, hi = span
        level = (np.clip((dd - lo) / max(hi - lo, 1e-6), 0, 1) * 255).astype(np.uint8)
        rgb = cv2.applyColorMap(level.reshape(-1, 1), cv2.COLORMAP_TURBO)[:, 0, ::-1].copy()
    return pts, rgb


def cloud_bytes(points: np.ndarray, rgb: np.ndarray) -> bytes:
    """u32 count, then x y z float32 per point, then r g b bytes per point (little-endian)."""
    return struct.pack("<I", len(points)) + points.astype("<f4").tobytes() + rgb.astype(np.uint8).tobytes()
