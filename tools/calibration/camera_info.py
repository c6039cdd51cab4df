"""ROS camera_info files of a stereo calibration, at any stream resolution the unit offers.

A stream of W×H pixels is the full calibration scaled (StereoCalibration.scaled) and rectified as
the device does it (protocol/rectification.py, SPEC §12.6), so R and P in these files are the
geometry of the rectified frames the unit sends at that size.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.params import BY_NAME
from stereocam.protocol.rectification import stereo_rectify


def ros_camera_info(name: str, size: tuple[int, int], K: np.ndarray, D: np.ndarray,
                    R: np.ndarray, P: np.ndarray, lens_model: str = "plumb_bob") -> str:
    """A ROS camera_info YAML document (camera_calibration_parsers layout)."""
    lines = [f"image_width: {size[0]}", f"image_height: {size[1]}", f"camera_name: {name}"]
    for key, value in (("camera_matrix", K), ("distortion_model", None), ("distortion_coefficients", D),
                       ("rectification_matrix", R), ("projection_matrix", P)):
        if value is None:
            lines.append(f"distortion_model: {lens_model}")
            continue
        a = np.atleast_2d(value)
        lines += [f"{key}:", f"  rows: {a.shape[0]}", f"  cols: {a.shape[1]}",
                  "  data: [" + ", ".join(repr(float(v)) for v in a.ravel()) + "]"]
    return "\n".join(lines) + "\n"


KALIBR_MODELS = {"plumb_bob": "radtan", "equidistant": "equidistant"}  # Kalibr has no rational model
K3_LIMIT_PX = 0.05


def _k3_shift_px(K: np.ndarray, D: np.ndarray, size: tuple[int, int]) -> float:
    """How far k3 moves the farthest image corner (px): |k3| r^7 fx, r its normalised radius."""
    w, h = size
    r = max(np.hypot((x - K[0, 2]) / K[0, 0], (y - K[1, 2]) / K[1, 1]) for x in (0, w) for y in (0, h))
    return float(abs(D[4]) * r ** 7 * K[0, 0])


def kalibr_camchain(calib: StereoCalibration, topics: tuple[str, str] = ("/cam0/image_raw", "/cam1/image_raw")
                    ) -> str | None:
    """A Kalibr camchain yaml (cam0 = left, cam1 = right, T_cn_cnm1 = [R T; 0 1], X_cam1 = R X_cam0 + T),
    or None for a lens model Kalibr cannot hold: rational_polynomial, or plumb_bob whose k3 moves an
    image corner by more than K3_LIMIT_PX (Kalibr's radtan has k1, k2, p1, p2 only)."""
    model = KALIBR_MODELS.get(calib.lens_model)
    if model is None or (calib.lens_model == "plumb_bob" and max(
            _k3_shift_px(K, D, calib.image_size) for K, D in ((calib.K_left, calib.D_left),
                                                              (calib.K_right, calib.D_right))) > K3_LIMIT_PX):
        return None

    def row(values: np.ndarray) -> str:
        return "[" + ", ".join(repr(float(v)) for v in values) + "]"

    T = np.eye(4)
    T[:3, :3], T[:3, 3] = calib.R, np.ravel(calib.T)
    lines = []
    for n, (K, D, topic) in enumerate(((calib.K_left, calib.D_left, topics[0]),
                                       (calib.K_right, calib.D_right, topics[1]))):
        lines.append(f"cam{n}:")
        if n:
            lines += ["  T_cn_cnm1:"] + [f"  - {row(r)}" for r in T]
        lines += ["  cam_overlaps: [" + str(1 - n) + "]", "  camera_model: pinhole",
                  f"  distortion_coeffs: {row(np.ravel(D)[:4])}", f"  distortion_model: {model}",
                  f"  intrinsics: {row(np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]]))}",
                  f"  resolution: [{calib.image_size[0]}, {calib.image_size[1]}]", f"  rostopic: {topic}"]
    return "\n".join(lines) + "\n"


def stream_sizes(sensor: tuple[int, int]) -> list[tuple[int, int]]:
    """Output sizes a unit offers for whole-frame streams: the sensor size divided by 1, 2, 4 and 8
    where the width/height parameters (SPEC §5.1) accept the result, and the default size."""
    w_param, h_param = BY_NAME["width"], BY_NAME["height"]
    sizes = [(sensor[0] // k, sensor[1] // k) for k in (1, 2, 4, 8)
             if sensor[0] % k == 0 and sensor[1] % k == 0]
    sizes.append((w_param.default, h_param.default))
    ok = [s for s in sizes if w_param.check(s[0]) is None and h_param.check(s[1]) is None]
    return sorted(set(ok), reverse=True)


def write_camera_info(calib: StereoCalibration, outdir: Path, size: tuple[int, int]) -> list[Path]:
    """left_WxH.yaml and right_WxH.yaml for streams of `size`; returns the paths."""
    c = calib if size == calib.image_size else calib.scaled(*size)
    g = stereo_rectify(c)
    outdir.mkdir(parents=True, exist_ok=True)
    paths = [outdir / f"left_{size[0]}x{size[1]}.yaml", outdir / f"right_{size[0]}x{size[1]}.yaml"]
    paths[0].write_text(ros_camera_info("left", size, c.K_left, c.D_left, g.R1, g.P1, c.lens_model))
    paths[1].write_text(ros_camera_info("right", size, c.K_right, c.D_right, g.R2, g.P2, c.lens_model))
    return paths
