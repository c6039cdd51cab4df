"""Whether this firmware can use a calibration body (SPEC §12.3): well formed, physically plausible
for this rig (protocol/calibration_limits.py), and able to build rectification maps that show the
sensors' pixels. A body that fails is refused before anything touches the flash."""
from __future__ import annotations

import numpy as np

from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.calibration_limits import CalibrationImplausible, PlausibilityLimits, check_plausible

from .rectify import rectification_maps

PROBE_WIDTH = 160  # maps are tried at this width (the calibration scaled): cheap, same geometry
MIN_INSIDE = 0.5  # share of rectified pixels that must sample inside the raw image, per camera
MIN_ORDERED = 0.99  # share of neighbouring rectified pixels whose raw samples keep their order (no fold)


def check_rectifiable(calib: StereoCalibration) -> None:
    """Raise CalibrationImplausible unless rectification maps can be built and mostly see the sensor."""
    w, h = calib.image_size
    pw = min(w, PROBE_WIDTH)
    ph = max(1, round(h * pw / w))
    try:
        with np.errstate(all="ignore"):
            maps = rectification_maps(calib.scaled(pw, ph))
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        raise CalibrationImplausible("rectification", f"no rectification possible: {exc}") from exc
    g = maps.geometry
    if not (np.isfinite(g.focal_px) and g.focal_px > 0 and np.isfinite(g.P2).all() and np.isfinite(g.Q).all()):
        raise CalibrationImplausible("rectification", f"rectification gives no usable view (focal "
                                     f"{g.focal_px:.6g} px)")
    for side, mx, my in (("left", maps.left_x, maps.left_y), ("right", maps.right_x, maps.right_y)):
        inside = float(np.mean(inside_mask(mx, my, pw, ph)))
        if not inside >= MIN_INSIDE:
            raise CalibrationImplausible("rectification", f"the rectified {side} view sees the sensor in only "
                                         f"{inside:.0%} of its pixels (at least {MIN_INSIDE:.0%} needed)")
        mask = inside_mask(mx, my, pw, ph)
        ordered = min(_ordered(mx, mask, 1), _ordered(my, mask, 0))
        if not ordered >= MIN_ORDERED:
            raise CalibrationImplausible("rectification", f"the {side} lens model folds the image: only "
                                         f"{ordered:.0%} of neighbouring pixels keep their order (distortion)")


def inside_mask(mx: np.ndarray, my: np.ndarray, w: int, h: int) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        return (mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)


def _ordered(coord: np.ndarray, inside: np.ndarray, axis: int) -> float:
    """Share of neighbour pairs (both inside) along ``axis`` whose sample coordinate increases."""
    both = np.logical_and(*(np.moveaxis(inside, axis, 0)[s] for s in (np.s_[1:], np.s_[:-1])))
    steps = np.diff(np.moveaxis(coord, axis, 0).astype(np.float64), axis=0)
    return float(np.mean(steps[both] > 0)) if both.any() else 0.0


def usable_calibration(body: bytes, limits: PlausibilityLimits) -> StereoCalibration:
    """The calibration in ``body``; CalibrationFormatError (or its CalibrationImplausible) naming why not."""
    calib = StereoCalibration.from_bytes(body)
    check_plausible(calib, limits)
    check_rectifiable(calib)
    return calib
