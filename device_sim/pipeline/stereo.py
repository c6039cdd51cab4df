"""The matching stage: block matching or SGM, configured from the device parameters (SPEC §5.1)."""
from __future__ import annotations

from typing import Mapping

import numpy as np

from stereocam.stereo import Matcher, MatchParams, SGMMatcher, SGMParams

BLOCK_MATCHING, SEMI_GLOBAL = 0, 1  # values of the ``algorithm`` parameter


def params_from_config(cfg: Mapping[str, int]) -> MatchParams | SGMParams:
    """Block-matching or SGM parameters per ``cfg["algorithm"]``."""
    if cfg.get("algorithm", BLOCK_MATCHING) == SEMI_GLOBAL:  # recordings made before 1.2 have no algorithm
        return SGMParams(
            num_disparities=cfg["num_disparities"], min_disparity=cfg["min_disparity"],
            census_width=cfg["census_width"], census_height=cfg["census_height"],
            paths=cfg["sgm_paths"], p1=cfg["sgm_p1"], p2=cfg["sgm_p2"],
            p2_adapt=cfg["sgm_p2_adapt"], uniqueness_ratio=cfg["uniqueness_ratio"],
            lr_max_diff=cfg["disp12_max_diff"], speckle_window_size=cfg["speckle_window_size"],
            speckle_range=cfg["speckle_range"])
    return MatchParams(
        num_disparities=cfg["num_disparities"], block_size=cfg["block_size"], min_disparity=cfg["min_disparity"],
        pre_filter_type="normalized" if cfg["pre_filter_type"] else "xsobel",
        pre_filter_size=cfg["pre_filter_size"], pre_filter_cap=cfg["pre_filter_cap"],
        texture_threshold=cfg["texture_threshold"], uniqueness_ratio=cfg["uniqueness_ratio"],
        speckle_window_size=cfg["speckle_window_size"], speckle_range=cfg["speckle_range"],
        disp12_max_diff=cfg["disp12_max_diff"])


def matcher_for(cfg: Mapping[str, int], shape: tuple[int, int],
                current: Matcher | SGMMatcher | None = None) -> Matcher | SGMMatcher:
    """``current`` when it already matches (cfg, shape), else a new matcher for them."""
    params = params_from_config(cfg)
    if current is not None and current.params == params and current.shape == tuple(shape):
        return current
    return (SGMMatcher if isinstance(params, SGMParams) else Matcher)(tuple(shape), params)


class StereoStage:
    """Disparity of a rectified pair; the matcher is rebuilt only when its settings or the format change."""

    def __init__(self) -> None:
        self._matcher: Matcher | SGMMatcher | None = None

    def disparity(self, cfg: dict[str, int], left: np.ndarray, right: np.ndarray) -> np.ndarray:
        self._matcher = matcher_for(cfg, left.shape, self._matcher)
        return self._matcher.match(left, right)
