"""The viewer's snapshots of the newest frame, as files to download: the images as PNG, the
disparity as data (raw int16 .npy as the device sends it, 16-bit PNG) and as a picture with a
depth colour bar, and the point cloud as PLY coloured by depth or by the left image."""
from __future__ import annotations

import io
import tempfile
from pathlib import Path

import cv2
import numpy as np

import stereocam

from .cloud import sampled_points
from stereocam.tools.camera.pictures import save_disparity_png

SNAPSHOTS = ("left.png", "right.png", "disparity.png", "disparity.npy", "disparity16.png", "points.ply")
MEDIA = {".png": "image/png", ".npy": "application/octet-stream", ".ply": "application/octet-stream"}


class MissingSnapshot(LookupError):
    """The newest frame lacks the plane a snapshot needs."""


def disparity16(frame: stereocam.Frame) -> np.ndarray:
    """The disparity as uint16 in the device's units (1/subpixel px), 0 where invalid or negative."""
    d = frame.disparity
    assert d is not None
    fmt = frame.disparity_format
    out = np.where((d == fmt.invalid) | (d < 0), 0, d)
    return out.astype(np.uint16)


def snapshot(frame: stereocam.Frame, name: str, colour: str, span: tuple[float, float]) -> bytes:
    """The bytes of snapshot ``name`` of ``frame``; MissingSnapshot if the frame lacks its plane."""
    plane = "disparity" if name.startswith(("disparity", "points")) else name.split(".")[0]
    img = getattr(frame, plane)
    if img is None:
        raise MissingSnapshot(f"the newest frame has no {plane} plane")
    if name in ("left.png", "right.png"):
        return cv2.imencode(".png", img)[1].tobytes()
    if name == "disparity16.png":
        return cv2.imencode(".png", disparity16(frame))[1].tobytes()
    if name == "disparity.npy":
        buf = io.BytesIO()
        np.save(buf, img)
        return buf.getvalue()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / name
        if name == "disparity.png":
            save_disparity_png(frame, path)
        else:
            points, rgb = sampled_points(frame, 1, colour, span)
            stereocam.write_ply(path, points, rgb=rgb)
        return path.read_bytes()
