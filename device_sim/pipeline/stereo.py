"""The matching stage: the disparity engine configured from the device parameters (SPEC §5.1).

The engine is built from the configuration by ``_engine_for``; block matching is the only one
today. The SGM engine (device_sim/matching, selected by an ``algorithm`` parameter) plugs in
there: its settings from the configuration, and how to build it for a format.
"""
from __future__ import annotations

from typing import Hashable

import numpy as np

from ..matching import Matcher, MatchParams


def match_params(cfg: dict[str, int]) -> MatchParams:
    """The block matcher settings a configuration asks for."""
    return MatchParams(
        num_disparities=cfg["num_disparities"], block_size=cfg["block_size"], min_disparity=cfg["min_disparity"],
        pre_filter_type="normalized" if cfg["pre_filter_type"] else "xsobel",
        pre_filter_size=cfg["pre_filter_size"], pre_filter_cap=cfg["pre_filter_cap"],
        texture_threshold=cfg["texture_threshold"], uniqueness_ratio=cfg["uniqueness_ratio"],
        speckle_window_size=cfg["speckle_window_size"], speckle_range=cfg["speckle_range"],
        disp12_max_diff=cfg["disp12_max_diff"])


def _engine_for(cfg: dict[str, int]) -> tuple[Hashable, type]:
    """(the engine's settings, its class: ``cls(shape, settings).match(left, right)``) that a
    configuration asks for. The SGM engine adds its branch here."""
    return match_params(cfg), Matcher


class StereoStage:
    """Disparity of a rectified pair; the engine is rebuilt only when its settings or the format change."""

    def __init__(self) -> None:
        self._key: tuple[Hashable, tuple[int, ...]] | None = None
        self._engine: Matcher | None = None

    def disparity(self, cfg: dict[str, int], left: np.ndarray, right: np.ndarray) -> np.ndarray:
        settings, engine = _engine_for(cfg)
        if self._engine is None or self._key != (settings, left.shape):
            self._engine = engine(left.shape, settings)
            self._key = (settings, left.shape)
        return self._engine.match(left, right)
