"""The post-processing chain in its fixed order (SPEC §5.3): left-right check, hole filling, spatial
filter, temporal filter, median, decimation. ``PostChain`` keeps the temporal state between frames;
``postprocess`` runs the chain once on the host (bench, rematch) exactly as the device does."""
from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from stereocam.protocol.errors import ConfigError
from stereocam.protocol.frame_messages import invalid_disparity
from stereocam.protocol.params import BY_NAME

from .confidence import confidence
from .decimation import decimate
from .holes import fill_background, fill_nearest
from .lr_check import lr_check, right_view_disparity
from .median import median_filter
from .params import PostParams
from .spatial import spatial_filter
from .temporal import TemporalState, temporal_filter

STAGES = ("lr_check", "hole_fill", "spatial", "temporal", "median", "decimation")
"""The stages, in the order they run."""

RightView = Callable[[], np.ndarray]
"""Computes the right view's disparity when the left-right check asks for it."""


class PostChain:
    """The chain for one setting and disparity range; ``run`` once per frame, in capture order."""

    def __init__(self, params: PostParams, min_disparity: int = 0) -> None:
        if not isinstance(params, PostParams):
            raise ValueError(f"params must be PostParams, got {type(params).__name__}")
        if isinstance(min_disparity, bool) or not isinstance(min_disparity, (int, np.integer)):
            raise ConfigError(f"min_disparity must be an int, got {type(min_disparity).__name__}")
        why = BY_NAME["min_disparity"].check(int(min_disparity))
        if why:
            raise ConfigError(why)
        self.params = params
        self.invalid = invalid_disparity(int(min_disparity))
        self.temporal = TemporalState()
        self.stage_ms: dict[str, float] = dict.fromkeys(STAGES, 0.0)  # the last run's time per stage
        self.confidence: np.ndarray | None = None  # the last run's confidence plane, when asked for

    def reset(self) -> None:
        """Forget the temporal filter's past (a configuration change, a trigger gap)."""
        self.temporal.reset()

    def run(self, disparity: np.ndarray, right_view: RightView | None = None, with_confidence: bool = False
            ) -> np.ndarray:
        """The filtered copy of ``disparity`` (int16, disparity * 16). ``right_view`` gives the right
        view's disparity when the left-right check is on (ConfigError when it is missing);
        ``with_confidence``: the confidence plane of the result goes to ``self.confidence``."""
        p, inv = self.params, self.invalid
        disp = _disparity_map(disparity, "disparity")
        t = time.perf_counter()
        if p.lr_check >= 0:
            if right_view is None:
                raise ConfigError("lr_check needs the right view's disparity (the right image and the engine)")
            right = _disparity_map(right_view(), "the right view's disparity")
            if right.shape != disp.shape:
                raise ValueError(f"the right view's disparity is {right.shape[1]}x{right.shape[0]}, "
                                 f"the map {disp.shape[1]}x{disp.shape[0]}")
            lr_check(disp, right, p.lr_check, inv)
            t = self._took("lr_check", t)
        matched = disp.copy() if with_confidence else None
        if p.hole_fill == 1:
            fill_nearest(disp, inv)
        elif p.hole_fill == 2:
            fill_background(disp, inv, np.empty((2, *disp.shape), np.int16))
        t = self._took("hole_fill", t)
        if p.spatial_alpha:
            spatial_filter(disp, p.spatial_alpha, p.spatial_delta, p.spatial_iterations, inv)
        t = self._took("spatial", t)
        if p.temporal_alpha:
            temporal_filter(disp, self.temporal, p.temporal_alpha, p.temporal_delta, p.temporal_persistence, inv)
        t = self._took("temporal", t)
        if p.median_size > 1:
            out = np.empty_like(disp)
            median_filter(disp, p.median_size, out)
            disp = out
        t = self._took("median", t)
        if p.decimation > 1:
            decimate(disp, p.decimation, inv)
        self._took("decimation", t)
        if matched is not None:
            self.confidence = np.empty(disp.shape, np.uint8)
            confidence(matched, disp, inv, self.confidence)
        return disp

    def _took(self, stage: str, since: float) -> float:
        now = time.perf_counter()
        self.stage_ms[stage] = (now - since) * 1e3
        return now


def _disparity_map(disparity: object, name: str) -> np.ndarray:
    """A C-contiguous int16 copy of a disparity map (1/16 px codes), or ValueError naming what
    is wrong: not a 2-D array, empty, not of integers, or values outside int16."""
    if not isinstance(disparity, np.ndarray):
        raise ValueError(f"{name} must be a numpy array, got {type(disparity).__name__}")
    if disparity.ndim != 2:
        raise ValueError(f"{name} must be 2-D, got shape {disparity.shape}")
    if disparity.size == 0:
        raise ValueError(f"{name} is empty ({disparity.shape[1]}x{disparity.shape[0]})")
    if disparity.dtype == np.bool_ or not np.issubdtype(disparity.dtype, np.integer):
        raise ValueError(f"{name} must be int16 (disparity * 16), got {disparity.dtype}")
    if disparity.dtype != np.int16:
        lo, hi = int(disparity.min()), int(disparity.max())
        if lo < -32768 or hi > 32767:
            raise ValueError(f"{name} holds {lo}..{hi}, outside int16 (disparity * 16)")
    return np.array(disparity, dtype=np.int16, order="C", copy=True)


def postprocess(disparity: np.ndarray, left: np.ndarray, params: PostParams, right: np.ndarray | None = None,
                engine_params: object | None = None, state: PostChain | None = None) -> np.ndarray:
    """Run the chain once on a disparity map the engine of ``engine_params`` made from (left, right).

    ``engine_params`` (MatchParams or SGMParams) give the invalid code and, with ``right``, the
    right view for the left-right check; ``state``: a PostChain whose temporal state carries on
    (its params are used)."""
    from ..engines import match  # the engines pull in every kernel; the chain alone needs none

    if not isinstance(left, np.ndarray) or not isinstance(disparity, np.ndarray) \
            or disparity.shape != left.shape:
        raise ValueError(f"disparity {getattr(disparity, 'shape', None)} and left image "
                         f"{getattr(left, 'shape', None)} differ in shape")
    min_disparity = getattr(engine_params, "min_disparity", 0)
    chain = state if state is not None else PostChain(params, min_disparity)
    right_view = None
    if right is not None and engine_params is not None:
        def right_view() -> np.ndarray:
            return right_view_disparity(lambda a, b: match(a, b, engine_params), left, right)
    return chain.run(disparity, right_view)
