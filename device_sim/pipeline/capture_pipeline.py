"""One capture, start to finish: expose both sensors, rectify with the calibration in force,
match, and send it as messages (protocol/segmentation.py) — on the capture engine's thread."""
from __future__ import annotations

import collections
from typing import Callable

import numpy as np

from stereocam.protocol import messages as m
from stereocam.protocol.params import Output
from stereocam.protocol.segmentation import capture_messages, plane_bytes

from ..clock import DeviceClock
from ..ground_truth import Exposure, TruthLog
from ..handlers.calibration import CalibrationService
from ..handlers.config_store import ConfigStore
from ..handlers.frame_repair import FrameRepair
from ..matching import warm_up as matching_warm_up
from ..rig.scene import Scene
from ..rig.sensor import Geometry, SensorRig
from .capture_engine import CaptureRequest
from .stereo import StereoStage

Send = Callable[[CaptureRequest, bytes], bool]  # one message of a capture; False: stop sending it


class CapturePipeline:
    def __init__(self, seed: int, rig: SensorRig, store: ConfigStore, calibration: CalibrationService,
                 clock: DeviceClock, truth: TruthLog, send: Send, counters: collections.Counter[str],
                 repair: FrameRepair):
        self.scene = Scene.LAB  # what the rig looks at (a simulator setting)
        self._seed = seed
        self._rig = rig
        self._store = store
        self._calibration = calibration
        self._clock = clock
        self._truth = truth
        self._send = send
        self._counters = counters
        self._repair = repair  # the link's chunk size, and recent captures kept for FRAME_RESEND
        self._stereo = StereoStage()
        self._view_rays: dict[Geometry, np.ndarray] = {}

    def warm_up(self) -> None:
        """What firmware does before it answers: compile (or load from numba's cache) every kernel
        of the capture path, so the first frames are not stalled. Paid once per process."""
        matching_warm_up()
        self._rig.set_format(64, 48)  # a tiny format: the real one is set by the first capture
        left, right = self._rig.capture(0.0, Scene.LAB, 4000, 0, 0)
        maps, _ = self._calibration.maps(64, 48)
        if maps is not None:
            maps.rectify(left, right)

    def produce(self, req: CaptureRequest) -> None:
        cfg = self._store.snapshot()
        w, h = cfg["width"], cfg["height"]
        self._rig.set_format(w, h)
        t = req.time - self._clock.boot
        view = self.scene
        left, right = self._rig.capture(t, view, cfg["exposure_us"], cfg["gain"], req.sequence ^ (self._seed << 20))
        maps, calib_id = self._calibration.maps(w, h)
        if not cfg["rectify"]:
            maps = None
        outputs = Output(cfg["outputs"])
        if maps is not None:  # on-board rectification from the stored calibration
            left, right = maps.rectify(left, right)
            g = maps.geometry
            focal, cx, cy, baseline = g.focal_px, g.cx, g.cy, g.baseline_m
            geometry = Geometry(w, h, focal, cx, cy, baseline)
            if geometry not in self._view_rays:
                self._view_rays = {geometry: geometry.rays()}  # one table per rectified view, not per frame
            self._truth.remember(Exposure(req.sequence, req.time, t, view, self._view_rays[geometry], g.R1.T,
                                          focal, baseline))
            flags = m.FRAME_RECTIFIED
        else:  # raw images: no disparity without a calibration
            outputs &= ~Output.DISPARITY
            focal = cx = cy = baseline = 0.0
            self._truth.remember(Exposure(req.sequence, req.time, t, view, self._rig.left_rays, np.eye(3), 0.0, 0.0))
            flags = 0
        disp = self._stereo.disparity(cfg, left, right) if Output.DISPARITY in outputs else None
        begin = m.FrameBegin(
            req.sequence & 0xFFFFFFFF, req.trigger_id & 0xFFFFFFFF, self._clock.at(req.time), cfg["exposure_us"],
            cfg["gain"], w, h, int(outputs), flags, m.DISPARITY_S16_Q4, 16, cfg["min_disparity"],
            cfg["num_disparities"], (cfg["min_disparity"] - 1) * 16, calib_id, focal, cx, cy, baseline)
        images = {Output.LEFT: left, Output.RIGHT: right, Output.DISPARITY: disp}
        raw = plane_bytes(begin, images, copy=True)  # kept unchanged for FRAME_RESEND
        self._repair.remember(req.sequence, {int(p): v for p, v in raw.items()})
        for msg in capture_messages(begin, raw, self._repair.chunk):
            if not self._send(req, m.encode(msg)):
                return  # the link went, or the stream was stopped: cut off at a message boundary
        self._counters["frames_sent"] += 1
