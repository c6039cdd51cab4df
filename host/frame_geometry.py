"""The geometry a host gives rectified frames: derived here from the calibration read from the
device (cached per calibration id and size) and cross-checked against what the device put in
each frame."""
from __future__ import annotations

import math
from typing import Callable

from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.rectification import stereo_rectify

from .calibration_io import StoredCalibration
from .frames import Frame, StereoGeometry


class FrameGeometry:
    """``read_active`` reads the calibration in force from the device (None: none stored)."""

    def __init__(self, read_active: Callable[[], StoredCalibration | None]):
        self._read_active = read_active
        self._cache: dict[tuple[int, int, int], tuple[StereoCalibration, StereoGeometry]] = {}
        self.mismatches = 0  # frames whose carried geometry disagreed with the stored calibration

    def apply(self, frame: Frame) -> Frame:
        """Give a rectified frame the geometry derived from the stored calibration it names; a raw
        frame, or one whose calibration changed since it was taken, keeps its own."""
        cid = frame.geometry.calibration_id
        if not frame.rectified or not cid:
            return frame
        key = (cid, frame.width, frame.height)
        if key not in self._cache:
            stored = self._read_active()
            if stored is None or stored.calibration_id != cid:  # changed since this frame was taken
                return frame
            cal = stored.calibration.scaled(frame.width, frame.height)
            g = stereo_rectify(cal)
            self._cache[key] = (cal, StereoGeometry(g.focal_px, g.cx, g.cy, g.baseline_m, cid))
        cal, geometry = self._cache[key]
        carried = frame.geometry
        if not (math.isclose(carried.focal_px, geometry.focal_px, rel_tol=1e-5)
                and math.isclose(carried.baseline_m, geometry.baseline_m, rel_tol=1e-5)
                and abs(carried.cx - geometry.cx) < 1e-3 and abs(carried.cy - geometry.cy) < 1e-3):
            self.mismatches += 1
        frame.geometry, frame.calibration = geometry, cal
        return frame
