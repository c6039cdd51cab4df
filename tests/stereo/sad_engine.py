"""An example matching engine in one module: plain numpy SAD and winner-take-all. The engine-table
test registers its ``ENGINE`` row and runs it through the device pipeline's and rematch's path."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from stereocam.protocol.frame_messages import DISPARITY_SUBPIXEL, invalid_disparity
from stereocam.stereo.config_map import ConfigField, check_params
from stereocam.stereo.engines import Engine

ALGORITHM = 2  # the value a protocol row would give it (the table allows 0..1 today)

SAD_CONFIG: tuple[ConfigField, ...] = (
    ConfigField("num_disparities"), ConfigField("min_disparity"), ConfigField("block_size", "window"),
)


@dataclass(frozen=True)
class SADParams:
    """Disparity range and a square window (limits: the protocol's)."""

    num_disparities: int = 16
    min_disparity: int = 0
    window: int = 5

    def __post_init__(self) -> None:
        check_params(self, SAD_CONFIG)


def sad_disparity(left: np.ndarray, right: np.ndarray, p: SADParams) -> np.ndarray:
    """Disparity * 16 (int16) of the smallest window SAD; invalid where no window fits."""
    h, w = left.shape
    r = p.window // 2
    big = np.iinfo(np.int64).max
    costs = np.full((p.num_disparities, h, w), big, np.int64)
    lf, rt = left.astype(np.int64), right.astype(np.int64)
    for k in range(p.num_disparities):
        d = p.min_disparity + k
        diff = np.zeros((h, w), np.int64)
        outside = np.ones((h, w), np.int64)  # 1 where x - d leaves the right image
        lo, hi = max(d, 0), min(w, w + d)
        if hi > lo:
            diff[:, lo:hi] = np.abs(lf[:, lo:hi] - rt[:, lo - d:hi - d])
            outside[:, lo:hi] = 0
        sums = sliding_window_view(diff, (p.window, p.window)).sum(axis=(-1, -2))
        bad = sliding_window_view(outside, (p.window, p.window)).sum(axis=(-1, -2)) > 0
        costs[k, r:h - r, r:w - r] = np.where(bad, big, sums)
    best = costs.argmin(axis=0)
    disp = ((p.min_disparity + best) * DISPARITY_SUBPIXEL).astype(np.int16)
    disp[costs.min(axis=0) == big] = invalid_disparity(p.min_disparity)
    return disp


class SADMatcher:
    """The engine's matcher: nothing kept between frames."""

    def __init__(self, shape: tuple[int, int], params: SADParams) -> None:
        self.shape, self.params = shape, params

    def match(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        return sad_disparity(left, right, self.params)


ENGINE = Engine(ALGORITHM, "sad", SADParams, SAD_CONFIG, SADMatcher, warm_up=lambda: None)
