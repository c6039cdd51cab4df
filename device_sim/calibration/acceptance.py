"""Whether this firmware can use a calibration body (SPEC §12.4 step 4): well formed, physically plausible
for this rig (protocol/calibration_limits.py), and able to build rectification maps that show the
sensors' pixels. A body that fails is refused before anything touches the flash."""
from __future__ import annotations

from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.calibration_limits import PlausibilityLimits, check_plausible, check_rectifiable

from .rectify import undistort_rectify_map


def firmware_map(lens_model, K, D, R, P, size):
    """One camera's map as the firmware builds it for on-board rectification."""
    return undistort_rectify_map(K, D, R, P, size, lens_model)


def usable_calibration(body: bytes, limits: PlausibilityLimits) -> StereoCalibration:
    """The calibration in ``body``; CalibrationFormatError (or its CalibrationImplausible) naming why not."""
    calib = StereoCalibration.from_bytes(body)
    check_plausible(calib, limits)
    check_rectifiable(calib, firmware_map)
    return calib
