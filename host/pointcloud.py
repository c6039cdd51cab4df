"""Point clouds to PLY (binary little-endian, x y z float32 + colour (or grey) as r g b uchar)."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from stereocam.protocol.errors import ConfigError


def write_ply(path: str | Path, points: np.ndarray, grey: np.ndarray | None = None,
              rgb: np.ndarray | None = None) -> int:
    """Write ``points`` (N x 3, metres) with optional grey levels (N values, 0..255) or colours
    (``rgb``: N x 3 uint8); returns the vertex count. ConfigError naming the argument for points,
    grey or rgb of another shape or kind, or a path that cannot be written."""
    try:
        pts = np.asarray(points, dtype="<f4")
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"points must be an N x 3 array of numbers: {exc}") from exc
    if pts.ndim < 1 or pts.shape[-1] != 3:
        raise ConfigError(f"points must be an N x 3 array (x, y, z), got shape {pts.shape}")
    pts = pts.reshape(-1, 3)
    n = len(pts)
    if grey is None:
        g = np.full(n, 255, np.uint8)
    else:
        try:
            levels = np.asarray(grey, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"grey must be numbers 0..255: {exc}") from exc
        if len(levels) != n or not np.all((levels >= 0) & (levels <= 255)):
            raise ConfigError(f"grey must be {n} values in 0..255 (one per point), got {len(levels)} "
                              f"in {levels.min() if len(levels) else 0:g}..{levels.max() if len(levels) else 0:g}")
        g = levels.astype(np.uint8)
    if not isinstance(path, (str, os.PathLike)):
        raise ConfigError(f"write_ply needs a file path, got {path!r}")
    rec = np.empty(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("r", "u1"), ("g", "u1"), ("b", "u1")])
    rec["x"], rec["y"], rec["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    rec["r"] = rec["g"] = rec["b"] = g
    if rgb is not None:
        colours = np.asarray(rgb)
        if colours.shape != (n, 3) or colours.dtype != np.uint8:
            raise ConfigError(f"rgb must be {n} x 3 uint8 colours (one per point), got {colours.shape} {colours.dtype}")
        rec["r"], rec["g"], rec["b"] = colours[:, 0], colours[:, 1], colours[:, 2]
    header = ("ply\nformat binary_little_endian 1.0\ncomment stereocam point cloud, metres, left camera frame\n"
              f"element vertex {n}\nproperty float x\nproperty float y\nproperty float z\n"
              "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
    try:
        with open(path, "wb") as f:
            f.write(header.encode("ascii"))
            f.write(rec.tobytes())
    except OSError as exc:
        raise ConfigError(f"cannot write {path}: {exc.strerror or exc}") from exc
    return n
