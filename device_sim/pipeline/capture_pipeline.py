"""One capture, start to finish, in two overlapping stages: the capture engine's thread exposes
both sensors (``produce``) and hands the raw pair to the delivery thread, which rectifies with the
calibration in force and sends the capture as messages (protocol/segmentation.py) while the next
exposure is rendered, matching once the images are on the wire (the link carries them while the
disparity is computed). Per-stage times (ms) accumulate in ``profile``."""
from __future__ import annotations

import collections
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from stereocam.protocol import messages as m
from stereocam.protocol.frame_messages import DISPARITY_SUBPIXEL, invalid_disparity
from stereocam.protocol.params import Output
from stereocam.protocol.segmentation import PlaneSource, capture_messages
from stereocam.stereo.engines import warm_up as matching_warm_up

from ..clock import UnitClock
from ..ground_truth import Exposure, TruthLog
from ..handlers.calibration import CalibrationService
from ..handlers.config_store import ConfigStore
from ..handlers.frame_repair import FrameRepair
from ..rig.scene import Scene
from ..rig.sensor import Geometry, SensorRig
from ..replay import ReplaySource
from .capture_engine import CaptureRequest
from .handoff import Handoff
from .stereo import StereoStage

Send = Callable[[CaptureRequest, bytes], bool]  # one message of a capture; False: stop sending it
STAGES = ("render", "rectify", "match", "send")


@dataclass(frozen=True)
class Exposed:
    """A raw pair on its way from the exposure stage to the delivery stage."""

    req: CaptureRequest
    cfg: dict[str, int]  # the configuration in force at the exposure
    scene_time: float
    view: Scene
    left: np.ndarray
    right: np.ndarray


class StageProfile:
    """Wall time per stage per frame (ms), summed since the last ``reset``."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.frames = 0
        self.ms = dict.fromkeys(STAGES, 0.0)

    def add(self, stage: str, since: float) -> float:
        now = time.perf_counter()
        self.ms[stage] += (now - since) * 1e3
        return now

    def per_frame(self) -> dict[str, float]:
        """Mean ms per frame of every stage over the frames delivered since ``reset``."""
        return {k: v / max(self.frames, 1) for k, v in self.ms.items()}


class CapturePipeline:
    def __init__(self, seed: int, rig: SensorRig, store: ConfigStore, calibration: CalibrationService,
                 clock: UnitClock, truth: TruthLog, send: Send, counters: collections.Counter[str],
                 repair: FrameRepair, on_drop: Callable[[], None], source: ReplaySource | None = None):
        """``source``: a recording whose captures replace the rig's (replay.py). ``on_drop``: a
        capture the delivery stage failed on (it counts as dropped)."""
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
        self.source = source
        self._stereo = StereoStage()
        self._view_rays: dict[Geometry, np.ndarray] = {}
        self.profile = StageProfile()
        self._delivery: Handoff[Exposed] = Handoff(self._deliver, lambda _: on_drop(), "capture-delivery")

    def warm_up(self) -> None:
        """What firmware does before it answers: compile (or load from numba's cache) every kernel
        of the capture path, so the first frames are not stalled. Paid once per process."""
        matching_warm_up()
        self._rig.set_format(64, 48)  # a tiny format: the real one is set by the first capture
        left, right = self._rig.capture(0.0, Scene.LAB, 4000, 0, 0)
        maps, _ = self._calibration.maps(64, 48)
        if maps is not None:
            maps.rectify(left, right)

    @property
    def idle(self) -> bool:
        """No capture on its way through the delivery stage."""
        return self._delivery.idle

    def close(self) -> None:
        """Stop the delivery thread (after the capture engine has stopped producing)."""
        self._delivery.close()

    def produce(self, req: CaptureRequest) -> None:
        """Exposure stage (capture engine thread): render both raw images, hand them on."""
        t0 = time.perf_counter()
        cfg = self._store.snapshot()
        if self.source is not None:  # replay: the recorded capture, re-matched if the matching changed
            replayed = self.source.capture(req, cfg, self._stereo.disparity)
            return self._send_all(req, replayed.begin, replayed.planes, t0)
        self._rig.set_format(cfg["width"], cfg["height"])
        t = req.time - self._clock.boot
        view = self.scene
        left, right = self._rig.capture(t, view, cfg["exposure_us"], cfg["gain"], req.sequence ^ (self._seed << 20))
        self.profile.add("render", t0)
        self._delivery.put(Exposed(req, cfg, t, view, left, right))

    def _deliver(self, exp: Exposed) -> None:
        """Delivery stage (its own thread): rectify, match, frame and send one capture."""
        t0 = time.perf_counter()
        req, cfg, t, view = exp.req, exp.cfg, exp.scene_time, exp.view
        w, h = cfg["width"], cfg["height"]
        left, right = exp.left, exp.right
        maps, calib_id = self._calibration.maps(w, h, cfg["rectified_fov"])
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
        else:  # raw images: no disparity (nor its confidence) without a calibration
            outputs &= ~(Output.DISPARITY | Output.CONFIDENCE)
            focal = cx = cy = baseline = 0.0
            self._truth.remember(Exposure(req.sequence, req.time, t, view, self._rig.left_rays, np.eye(3), 0.0, 0.0))
            flags = 0
        t0 = self.profile.add("rectify", t0)
        begin = m.FrameBegin(
            req.sequence & 0xFFFFFFFF, req.trigger_id & 0xFFFFFFFF, self._clock.at(req.time), cfg["exposure_us"],
            cfg["gain"], w, h, int(outputs), flags, m.DISPARITY_S16_Q4, DISPARITY_SUBPIXEL, cfg["min_disparity"],
            cfg["num_disparities"], invalid_disparity(cfg["min_disparity"]), calib_id, focal, cx, cy, baseline)

        matched: list[np.ndarray | None] = []  # the confidence plane, once matched

        def match() -> np.ndarray:  # runs once the images are on their way: the link carries them meanwhile
            disp, conf = self._stereo.planes(cfg, left, right, req.time, bool(outputs & Output.CONFIDENCE))
            matched.append(conf)
            return disp

        def confidence() -> np.ndarray:  # sent after the disparity plane (or alone)
            if not matched:
                match()
            conf = matched[0]
            assert conf is not None
            return conf

        self._send_all(req, begin, {Output.LEFT: left, Output.RIGHT: right, Output.DISPARITY: match,
                                    Output.CONFIDENCE: confidence}, t0)

    def _send_all(self, req: CaptureRequest, begin: m.FrameBegin, images: Mapping[Output, PlaneSource],
                  t0: float) -> None:
        """Frame and send one capture (``t0``: when its send stage began, for the profile); a plane
        given as a function is computed when its turn comes."""
        kept: dict[int, memoryview] = {}  # each plane's bytes, unchanged, for FRAME_RESEND
        self._repair.remember(req.sequence, kept)
        matching = 0.0

        def computed(source: PlaneSource) -> PlaneSource:
            if not callable(source):
                return source

            def run() -> np.ndarray:
                nonlocal matching
                t = time.perf_counter()
                image = source()
                matching += self.profile.add("match", t) - t
                return image
            return run

        def keep(plane: Output, data: memoryview) -> None:
            kept[int(plane)] = memoryview(bytes(data))

        for msg in capture_messages(begin, {p: computed(v) for p, v in images.items()}, self._repair.chunk, keep):
            if not self._send(req, m.encode(msg)):
                return  # the link went, or the stream was stopped: cut off at a message boundary
        self.profile.add("send", t0 + matching)
        self.profile.frames += 1
        self._counters["frames_sent"] += 1
