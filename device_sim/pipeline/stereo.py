"""The matching stage: the block matcher configured from the device parameters (SPEC §5.1)."""
from __future__ import annotations

import numpy as np

from ..matching import Matcher, MatchParams


def match_params(cfg: dict[str, int]) -> MatchParams:
    """The matcher settings a configuration asks for."""
    return MatchParams(
        num_disparities=cfg["num_disparities"], block_size=cfg["block_size"], min_disparity=cfg["min_disparity"],
        pre_filter_type="normalized" if cfg["pre_filter_type"] else "xsobel",
        pre_filter_size=cfg["pre_filter_size"], pre_filter_cap=cfg["pre_filter_cap"],
        texture_threshold=cfg["texture_threshold"], uniqueness_ratio=cfg["uniqueness_ratio"],
        speckle_window_size=cfg["speckle_window_size"], speckle_range=cfg["speckle_range"],
        disp12_max_diff=cfg["disp12_max_diff"])


class StereoStage:
    """Disparity of a rectified pair; the matcher is rebuilt only when its settings or the format change."""

    def __init__(self) -> None:
        self._matcher: Matcher | None = None

    def disparity(self, cfg: dict[str, int], left: np.ndarray, right: np.ndarray) -> np.ndarray:
        params = match_params(cfg)
        if self._matcher is None or self._matcher.params != params or self._matcher.shape != left.shape:
            self._matcher = Matcher(left.shape, params)
        return self._matcher.match(left, right)
