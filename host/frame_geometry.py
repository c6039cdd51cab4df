"""The geometry a host gives rectified frames: derived here from the calibration read from the
device when it changes (on open, after a calibration is written, after a reconnect), never while a
frame is handed out, and cross-checked against what the device put in each frame.

An equidistant (fisheye) calibration's rectified focal length also depends on the device parameter
``rectified_fov`` (SPEC §12.6 step 3), which may change while streaming: its field of view is read
from the focal length the frame carries, f = max(f_fov, f_in) — so a carried f below the f_in
the calibration demands still counts as a mismatch — and cx, cy and B are checked as for every model."""
from __future__ import annotations

import math
import threading

from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.rectification import EQUIDISTANT_FOV_DEG, stereo_rectify

from .calibration_io import StoredCalibration
from .frame_types import Frame, StereoGeometry


class FrameGeometry:
    """The stored calibration in force (``resolve``) and, per frame size, the geometry it gives."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._stored: StoredCalibration | None = None
        self._cache: dict[tuple[int, int, float], tuple[StereoCalibration, StereoGeometry]] = {}
        self.mismatches = 0  # frames whose carried geometry disagreed with the stored calibration

    def resolve(self, stored: StoredCalibration | None) -> None:
        """The calibration now in force on the device (None: none stored), as just read from it."""
        with self._lock:
            self._stored, self._cache = stored, {}

    @property
    def calibration_id(self) -> int:
        """The id of the calibration resolved last (0: none)."""
        stored = self._stored
        return stored.calibration_id if stored is not None else 0

    def apply(self, frame: Frame) -> Frame:
        """Give a rectified frame the geometry derived from the stored calibration it names; a raw
        frame, or one taken under another calibration than the one resolved, keeps its own. No I/O."""
        cid = frame.geometry.calibration_id
        with self._lock:
            stored = self._stored
            if not frame.rectified or not cid or stored is None or stored.calibration_id != cid:
                return frame
            carried = frame.geometry
            fov = EQUIDISTANT_FOV_DEG
            if stored.calibration.lens_model == "equidistant" and carried.focal_px > 0:
                fov = math.degrees(2.0 * math.atan(frame.width / 2 / carried.focal_px))
            key = (frame.width, frame.height, fov)
            if key not in self._cache:
                if len(self._cache) > 16:  # a field of view swept while streaming
                    self._cache.clear()
                cal = stored.calibration.scaled(frame.width, frame.height)
                g = stereo_rectify(cal, fov)
                self._cache[key] = (cal, StereoGeometry(g.focal_px, g.cx, g.cy, g.baseline_m, cid))
            cal, geometry = self._cache[key]
            if not (math.isclose(carried.focal_px, geometry.focal_px, rel_tol=1e-5)
                    and math.isclose(carried.baseline_m, geometry.baseline_m, rel_tol=1e-5)
                    and abs(carried.cx - geometry.cx) < 1e-3 and abs(carried.cy - geometry.cy) < 1e-3):
                self.mismatches += 1
        frame.geometry, frame.calibration = geometry, cal
        return frame
