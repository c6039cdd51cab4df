"""What the simulator knows about each capture it made: depth and disparity truth, on demand.

A simulator-only facility (never on the wire): tests and tools ask ``SimulatedCamera.ground_truth``.
"""
from __future__ import annotations

import collections
import threading
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .rig.scene import Scene, primitives
from .rig.stereo_pair import occlusion
from .rig.sensor import SensorRig

GROUND_TRUTH_KEEP = 64  # captures remembered
INSTANTS_KEEP = 1 << 16  # exposure instants remembered (cheap: for timing benchmarks)


@dataclass(frozen=True)
class GroundTruth:
    """What the simulator knows about one capture, for the delivered left image's pixels."""

    sequence: int
    host_monotonic: float  # the exposure instant on the host's monotonic clock
    depth_m: np.ndarray  # along the delivered view's optical axis; inf where nothing was hit
    disparity_px: np.ndarray  # f * B / z for rectified frames, 0 where nothing was hit (or raw)
    occluded: np.ndarray | None = None  # rectified frames: a surface the right camera does not see


@dataclass(frozen=True)
class Exposure:
    """What the simulator needs to reconstruct the truth of one capture on demand."""

    sequence: int
    host_monotonic: float
    scene_time: float
    scene: Scene
    rays: np.ndarray  # camera-frame rays of the delivered left image (rectified pinhole or raw lens)
    rot: np.ndarray  # that view's camera→world rotation
    focal_px: float
    baseline_m: float


class TruthLog:
    """The exposures of the last ``GROUND_TRUTH_KEEP`` captures, rendered to truth when asked."""

    def __init__(self, rig: SensorRig):
        self._rig = rig
        self._exposures: collections.OrderedDict[int, Exposure] = collections.OrderedDict()
        self._instants: collections.OrderedDict[int, float] = collections.OrderedDict()
        self._lock = threading.Lock()
        self.on_exposure: Callable[[int, float], None] | None = None  # (sequence, host monotonic) per capture

    def remember(self, exposure: Exposure) -> None:
        with self._lock:
            self._exposures[exposure.sequence] = exposure
            while len(self._exposures) > GROUND_TRUTH_KEEP:
                self._exposures.popitem(last=False)
            self._instants[exposure.sequence] = exposure.host_monotonic
            while len(self._instants) > INSTANTS_KEEP:
                self._instants.popitem(last=False)
        if self.on_exposure is not None:
            self.on_exposure(exposure.sequence, exposure.host_monotonic)

    def exposure_instant(self, sequence: int) -> float | None:
        """The true exposure instant (host monotonic) of one of the last ``INSTANTS_KEEP`` captures."""
        with self._lock:
            return self._instants.get(sequence)

    def ground_truth(self, sequence: int) -> GroundTruth | None:
        """Truth for one of the last few captures (None once it has aged out, or for the board),
        rendered for exactly the view the frame delivered (rectified by the stored calibration, or raw)."""
        with self._lock:
            e = self._exposures.get(sequence)
        if e is None or e.scene == Scene.BOARD:
            return None
        depth = self._rig.depth(e.scene_time, e.scene, e.rays, e.rot)
        with np.errstate(divide="ignore"):
            disp = np.where(np.isfinite(depth) & (e.focal_px > 0), e.focal_px * e.baseline_m / depth, 0)
        occluded = None
        if e.focal_px > 0:
            rig = self._rig
            occluded = occlusion(e.rays, e.rot, depth, disp, rig.right_centre, primitives(e.scene, e.scene_time),
                                 (rig.texture, rig.tex_offsets, rig.tex_side))
        return GroundTruth(sequence, e.host_monotonic, depth, disp.astype(np.float32), occluded)
