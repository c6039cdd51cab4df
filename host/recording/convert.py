"""Frames and the unit's calibration as ROS 2 messages (plain dicts for the CDR encoders)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stereocam.frames import Frame
from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.params import Output
from stereocam.protocol.rectification import stereo_rectify

from .schemas import FRAME_IDS

DISPARITY_STEP = 1.0 / 16  # DisparityImage.delta_d: the camera's Q4 sub-pixel step


@dataclass(frozen=True)
class LinkCounters:
    """Drop counters so far, by where the loss happened (all cumulative)."""

    link_lost: int = 0
    link_incomplete: int = 0
    host_queue_overflow: int = 0
    device_dropped: int = 0
    recorder_dropped: int = 0


def stamp(ns: int) -> dict:
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def header(ns: int, frame_id: str) -> dict:
    return {"stamp": stamp(ns), "frame_id": frame_id}


def image(ns: int, frame_id: str, plane: np.ndarray) -> dict:
    """A mono8 Image; its ``data`` is set by the caller (see ``schemas.encode_with_blob``)."""
    h, w = plane.shape
    return {"header": header(ns, frame_id), "height": h, "width": w, "encoding": "mono8", "is_bigendian": 0,
            "step": w}


def blob(plane: np.ndarray) -> memoryview:
    """A plane's bytes without a copy."""
    return np.ascontiguousarray(plane).data.cast("B")


def disparity_to_float(frame: Frame) -> np.ndarray:
    """The camera's int16 Q4 plane in pixels (exact in float32; invalid → min_disparity - 1)."""
    return np.multiply(frame.disparity_plane(), np.float32(DISPARITY_STEP), dtype=np.float32)


def disparity_from_float(pixels: np.ndarray) -> np.ndarray:
    """Back to the camera's int16 Q4 plane, bit for bit."""
    return np.rint(pixels * 16).astype(np.int16)


def disparity(ns: int, frame: Frame) -> dict:
    """A DisparityImage; its ``image["data"]`` is set by the caller (float32 from ``disparity_to_float``)."""
    fmt, g = frame.disparity_format, frame.geometry
    h, w = frame.disparity_plane().shape
    img = {"header": header(ns, FRAME_IDS["left"]), "height": h, "width": w, "encoding": "32FC1",
           "is_bigendian": 0, "step": 4 * w}
    return {"header": header(ns, FRAME_IDS["left"]), "image": img, "f": g.focal_px, "t": g.baseline_m,
            "valid_window": {"x_offset": 0, "y_offset": 0, "height": h, "width": w, "do_rectify": False},
            "min_disparity": float(fmt.min_disparity),
            "max_disparity": float(fmt.min_disparity + fmt.num_disparities - 1), "delta_d": DISPARITY_STEP}


def camera_infos(calibration: StereoCalibration | None, width: int, height: int, rectified: bool
                 ) -> tuple[dict, dict]:
    """CameraInfo bodies (no header) for both views of ``width`` x ``height`` frames: K, D of each
    imager and, for rectified frames, R1/R2 and P1/P2 (P2[0,3] = -f·B) from ``stereo_rectify``."""
    if calibration is None:
        empty = {"height": height, "width": width, "distortion_model": "", "d": [], "k": [0.0] * 9,
                 "r": [0.0] * 9, "p": [0.0] * 12, "binning_x": 0, "binning_y": 0, "roi": {}}
        return empty, dict(empty)
    cal = calibration.scaled(width, height)
    g = stereo_rectify(cal) if rectified else None
    out = []
    imagers = ((cal.K_left, cal.D_left), (cal.K_right, cal.D_right))
    rectifications = ((g.R1, g.P1), (g.R2, g.P2)) if g is not None else (None, None)
    for (K, D), rectification in zip(imagers, rectifications):
        # raw frames: the identity rotation and the imager's own projection
        R, P = rectification if rectification is not None else (np.eye(3), np.hstack([K, np.zeros((3, 1))]))
        out.append({"height": height, "width": width, "distortion_model": "plumb_bob",
                    "d": [float(v) for v in np.ravel(D)], "k": [float(v) for v in np.ravel(K)],
                    "r": [float(v) for v in np.ravel(R)], "p": [float(v) for v in np.ravel(P)],
                    "binning_x": 0, "binning_y": 0,
                    "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False}})
    return out[0], out[1]


def capture_info(ns: int, frame: Frame, counters: LinkCounters) -> dict:
    fmt, g = frame.disparity_format, frame.geometry
    planes = ((frame.left is not None) * Output.LEFT | (frame.right is not None) * Output.RIGHT
              | (frame.disparity is not None) * Output.DISPARITY | (frame.confidence is not None) * Output.CONFIDENCE)
    return {"header": header(ns, FRAME_IDS["left"]), "sequence": frame.sequence, "trigger_id": frame.trigger_id,
            "device_time_us": frame.device_time_us, "host_time": frame.host_time, "status": frame.status.value,
            "exposure_us": frame.exposure_us, "gain": frame.gain, "width": frame.width, "height": frame.height,
            "planes": int(planes), "rectified": frame.rectified, "subpixel": fmt.subpixel,
            "min_disparity": fmt.min_disparity, "num_disparities": fmt.num_disparities,
            "invalid_disparity": fmt.invalid, "calibration_id": g.calibration_id, "focal_px": g.focal_px,
            "cx": g.cx, "cy": g.cy, "baseline_m": g.baseline_m, **counters.__dict__}
