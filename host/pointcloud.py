"""Point clouds to PLY (binary little-endian, x y z float32 + grey as r g b uchar)."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def write_ply(path: str | Path, points: np.ndarray, grey: np.ndarray | None = None) -> int:
    """Write ``points`` (N x 3) with optional grey levels (N,); returns the vertex count."""
    pts = np.asarray(points, dtype="<f4").reshape(-1, 3)
    n = len(pts)
    g = np.full(n, 255, np.uint8) if grey is None else np.asarray(grey, np.uint8).reshape(n)
    rec = np.empty(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("r", "u1"), ("g", "u1"), ("b", "u1")])
    rec["x"], rec["y"], rec["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    rec["r"] = rec["g"] = rec["b"] = g
    header = ("ply\nformat binary_little_endian 1.0\ncomment stereocam point cloud, metres, left camera frame\n"
              f"element vertex {n}\nproperty float x\nproperty float y\nproperty float z\n"
              "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(rec.tobytes())
    return n
