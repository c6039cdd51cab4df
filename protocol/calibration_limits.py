"""What a stereo calibration must look like to be physically plausible (SPEC §12.3): the limits a
device checks before it stores a calibration, and a host may check before it sends one.

``StereoCalibration`` (calibration.py) only checks the form (shapes, finite numbers, a rotation
matrix). ``check_plausible`` adds the physics: focal lengths relative to the image size, pixel
aspect, principal points inside the image, baseline and relative rotation of the rig, distortion
magnitude, and the sensor's aspect ratio. The limits are deliberately wide — they must accept every
real camera (fy/fx of 0.85–1.2 exists, wide-angle lenses exist) and refuse only what cannot be a
camera at all; a device with narrower mechanical limits passes its own ``PlausibilityLimits``.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .calibration import CalibrationFormatError, StereoCalibration
from .rectification import stereo_rectify


class CalibrationImplausible(CalibrationFormatError):
    """A well-formed calibration no real rig can have; ``field`` names the offending quantity."""

    def __init__(self, field: str, message: str):
        super().__init__(message)
        self.field = field


@dataclass(frozen=True)
class PlausibilityLimits:
    """Wide physical limits; every bound is inclusive."""

    focal_rel: tuple[float, float] = (0.1, 20.0)
    """fx / image width and fy / image width: 0.1 ≈ a 175° fisheye, 20 ≈ a 3° telephoto."""
    pixel_aspect: tuple[float, float] = (0.5, 2.0)
    """fy / fx (real sets reach 0.85–1.2)."""
    principal_point_margin: float = 0.0
    """cx, cy within [-margin, size - 1 + margin] pixels: the optical axis meets the sensor."""
    baseline_m: tuple[float, float] = (0.005, 2.0)
    """|T| in metres: from a 5 mm board camera to a 2 m rail."""
    max_rotation_deg: float = 30.0
    """Angle of R: how far the two optical axes may be turned against each other."""
    max_distortion: float = 1000.0
    """|coefficient| of every distortion term. Wide: a rational_polynomial fit's numerator and
    denominator terms are often tens to hundreds each (their ratio is what matters); what a lens
    model really does to the image is judged by the rectification check (calibration/acceptance.py)."""
    sensor_size: tuple[int, int] | None = None
    """The rig's sensor (width, height): image_size must not exceed it and must keep its aspect
    ratio within ``aspect_tolerance`` (a device scales the calibration to every output format)."""
    aspect_tolerance: float = 0.02


DEFAULT_LIMITS = PlausibilityLimits()


# What rectification maps built from a calibration must do (SPEC §12.4 step 4). Each side builds
# the maps with its own engine (the firmware its remap tables, the host OpenCV) at the probe size.
PROBE_WIDTH = 160  # maps are tried at this width (the calibration scaled): cheap, same geometry
MIN_INSIDE = 0.5  # share of rectified pixels that must sample inside the raw image, per camera
MIN_ORDERED = 0.99  # share of neighbouring rectified pixels whose raw samples keep their order (no fold)


def probe_size(image_size: tuple[int, int]) -> tuple[int, int]:
    """The (width, height) at which rectification maps are checked."""
    w, h = image_size
    pw = min(w, PROBE_WIDTH)
    return pw, max(1, round(h * pw / w))


MapBuilder = Callable[[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple[int, int]],
                     tuple[np.ndarray, np.ndarray]]
"""(lens_model, K, D, R, P, (width, height)) -> (map_x, map_y): one camera's float maps, rectified
(u, v) -> raw (x, y), as cv2.initUndistortRectifyMap makes them."""


def check_rectifiable(calib: StereoCalibration, build_map: MapBuilder) -> None:
    """Raise CalibrationImplausible unless ``calib`` rectifies (finite geometry, positive focal) to
    views that sample each sensor in at least MIN_INSIDE of their pixels without folding
    (neighbouring rectified pixels keep the order of their raw samples in MIN_ORDERED of cases)."""
    small = calib.scaled(*probe_size(calib.image_size))
    try:
        with np.errstate(all="ignore"):
            g = stereo_rectify(small)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        raise CalibrationImplausible("rectification", f"no rectification possible: {exc}") from exc
    if not (np.isfinite(g.focal_px) and g.focal_px > 0 and np.isfinite(g.P2).all() and np.isfinite(g.Q).all()):
        raise CalibrationImplausible("rectification", f"rectification gives no usable view (focal "
                                     f"{g.focal_px:.6g} px)")
    for side, K, D, R, P in (("left", small.K_left, small.D_left, g.R1, g.P1),
                             ("right", small.K_right, small.D_right, g.R2, g.P2)):
        with np.errstate(all="ignore"):
            map_x, map_y = build_map(small.lens_model, K, D, R, P, g.image_size)
        h, w = map_x.shape
        with np.errstate(invalid="ignore"):
            inside = (map_x >= 0) & (map_x <= w - 1) & (map_y >= 0) & (map_y <= h - 1)
        share = float(np.mean(inside))
        if not share >= MIN_INSIDE:
            raise CalibrationImplausible("rectification", f"the rectified {side} view sees the sensor in only "
                                         f"{share:.0%} of its pixels (at least {MIN_INSIDE:.0%} needed)")
        ordered = min(_ordered(map_x, inside, 1), _ordered(map_y, inside, 0))
        if not ordered >= MIN_ORDERED:
            raise CalibrationImplausible("rectification", f"the {side} lens model folds the image: only "
                                         f"{ordered:.0%} of neighbouring pixels keep their order (distortion)")


def _ordered(coord: np.ndarray, inside: np.ndarray, axis: int) -> float:
    """Share of neighbour pairs (both inside) along ``axis`` whose sample coordinate increases."""
    both = np.logical_and(*(np.moveaxis(inside, axis, 0)[s] for s in (np.s_[1:], np.s_[:-1])))
    steps = np.diff(np.moveaxis(coord, axis, 0).astype(np.float64), axis=0)
    return float(np.mean(steps[both] > 0)) if both.any() else 0.0


def _within(value: float, bounds: tuple[float, float]) -> bool:
    return bounds[0] <= value <= bounds[1]


def check_plausible(calib: StereoCalibration, limits: PlausibilityLimits = DEFAULT_LIMITS) -> None:
    """Raise CalibrationImplausible naming the first implausible quantity of ``calib``."""
    w, h = calib.image_size
    if limits.sensor_size is not None:
        sw, sh = limits.sensor_size
        if w > sw or h > sh or abs((w / h) / (sw / sh) - 1.0) > limits.aspect_tolerance:
            raise CalibrationImplausible("image_size", f"image_size {w}x{h} is not a format of the {sw}x{sh} "
                                         "sensor (same aspect ratio, not larger)")
    m = limits.principal_point_margin
    for side in ("left", "right"):
        K = getattr(calib, f"K_{side}")
        fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
        for name, f in (("fx", fx), ("fy", fy)):
            if not _within(f / w, limits.focal_rel):
                lo, hi = (b * w for b in limits.focal_rel)
                raise CalibrationImplausible(f"K_{side}", f"K_{side} {name}={f:.6g} px outside {lo:.6g}..{hi:.6g} px "
                                             f"for a {w} px wide image")
        if not _within(fy / fx, limits.pixel_aspect):
            raise CalibrationImplausible(f"K_{side}", f"K_{side} fy/fx={fy / fx:.4g} outside "
                                         f"{limits.pixel_aspect[0]}..{limits.pixel_aspect[1]}")
        for name, c, size in (("cx", cx, w), ("cy", cy, h)):
            if not -m <= c <= size - 1 + m:
                raise CalibrationImplausible(f"K_{side}", f"K_{side} principal point {name}={c:.6g} px outside "
                                             f"the image (0..{size - 1})")
        D = np.asarray(getattr(calib, f"D_{side}"), np.float64)
        worst = float(np.max(np.abs(D))) if D.size else 0.0
        if worst > limits.max_distortion:
            raise CalibrationImplausible(f"D_{side}", f"D_{side} distortion coefficient of magnitude {worst:.6g} "
                                         f"beyond {limits.max_distortion}")
    with np.errstate(over="ignore"):  # |T| of 1e300 overflows to inf: outside any range
        baseline = calib.baseline_m
    if not _within(baseline, limits.baseline_m):
        raise CalibrationImplausible("T", f"baseline |T|={baseline:.6g} m outside {limits.baseline_m[0]}.."
                                     f"{limits.baseline_m[1]} m")
    angle = np.degrees(np.arccos(np.clip((np.trace(calib.R) - 1.0) / 2.0, -1.0, 1.0)))
    if angle > limits.max_rotation_deg:
        raise CalibrationImplausible("R", f"rotation between the cameras of {angle:.3g}° beyond "
                                     f"{limits.max_rotation_deg}°")
