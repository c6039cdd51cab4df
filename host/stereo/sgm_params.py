"""Semi-global matching parameters and the frame geometry they imply.

The algorithm (census cost, path aggregation, winner-take-all, uniqueness, subpixel, left-right
check) is specified once, in plain numpy, by tests/sgm_reference.py; the numba engine is
bit-exact with it.
"""
from __future__ import annotations

from dataclasses import dataclass

from .params import DISP_SHIFT, _check_int

PATH_COUNTS = (4, 8)
PATH_COST_LIMIT = 255  # path costs L <= census bits + p2 are held in uint8


@dataclass(frozen=True)
class SGMParams:
    """SGM parameters; the defaults are a good general setting (census 9x7, 8 paths)."""

    num_disparities: int = 128  # disparities min_disparity .. min_disparity + N - 1
    min_disparity: int = 0
    census_width: int = 9  # census window (odd, width * height - 1 <= 64 comparison bits)
    census_height: int = 7
    paths: int = 8  # 4 (horizontal + vertical) or 8 (plus the diagonals)
    p1: int = 15  # penalty for a 1 px disparity change between neighbours along a path
    p2: int = 128  # penalty for a larger change
    p2_adapt: int = 32  # > 0: P2 / (1 + |dI| / p2_adapt) along the path, not below p1 (nor
    # above p2); 0: off
    uniqueness_ratio: int = 0  # percent margin the best cost must keep over others (0: off)
    lr_max_diff: int = -1  # left-right check tolerance in px (< 0: off)
    speckle_window_size: int = 100  # regions of at most this many pixels are removed (0: off)
    speckle_range: int = 32  # 1/16 px: neighbours differing by more start a new region

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise ValueError naming the first invalid parameter."""
        for name in ("num_disparities", "min_disparity", "census_width", "census_height",
                     "paths", "p1", "p2", "p2_adapt", "uniqueness_ratio", "lr_max_diff",
                     "speckle_window_size", "speckle_range"):
            _check_int(name, getattr(self, name))
        nd = self.num_disparities
        if nd <= 0 or nd % 16 != 0:
            raise ValueError(f"num_disparities must be positive and divisible by 16, got {nd}")
        cw, ch = self.census_width, self.census_height
        if cw < 1 or ch < 1 or cw % 2 == 0 or ch % 2 == 0 or not 2 <= cw * ch <= 65:
            raise ValueError(f"census window must be odd by odd with 1..64 comparisons, "
                             f"got {cw}x{ch}")
        if self.paths not in PATH_COUNTS:
            raise ValueError(f"paths must be one of {PATH_COUNTS}, got {self.paths}")
        if not 0 <= self.p1 <= PATH_COST_LIMIT or self.p2 < 0:
            raise ValueError(f"penalties must satisfy 0 <= p1 <= {PATH_COST_LIMIT} and "
                             f"p2 >= 0, got p1={self.p1} p2={self.p2}")
        if self.max_cost + self.p2 > PATH_COST_LIMIT:
            raise ValueError(f"p2 {self.p2} too large: census bits {self.max_cost} + p2 must "
                             f"not exceed {PATH_COST_LIMIT}")
        for name in ("p2_adapt", "uniqueness_ratio", "speckle_window_size", "speckle_range"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be non-negative, got {getattr(self, name)}")
        lo, hi = (self.min_disparity - 1) * 16, (self.min_disparity + nd) * 16
        if lo < -32768 or hi > 32767:
            raise ValueError(f"min_disparity {self.min_disparity} with num_disparities {nd} "
                             "does not fit the int16 output")

    @property
    def max_cost(self) -> int:
        """Largest matching cost: the number of census comparison bits."""
        return self.census_width * self.census_height - 1

    @property
    def invalid_value(self) -> int:
        """Value written for pixels without a disparity: (min_disparity - 1) * 16."""
        return (self.min_disparity - 1) << DISP_SHIFT

    @property
    def use_speckle(self) -> bool:
        return self.speckle_window_size > 0


@dataclass(frozen=True)
class SGMGeometry:
    """Columns [x0, x1) where every disparity of the range has its right pixel in the image;
    only these are matched (the path rectangle), the rest of each row is invalid."""

    height: int
    width: int
    x0: int
    x1: int

    @property
    def cols(self) -> int:
        return self.x1 - self.x0


def sgm_geometry(height: int, width: int, p: SGMParams) -> SGMGeometry:
    """The matched column range; ValueError when the image cannot hold one."""
    x0 = max(p.min_disparity + p.num_disparities - 1, 0)
    x1 = min(width, width + p.min_disparity)
    if height < 1 or x1 - x0 < 1:
        raise ValueError(f"image {width}x{height} is too small for num_disparities "
                         f"{p.num_disparities} and min_disparity {p.min_disparity}: "
                         "no column can hold a valid disparity")
    return SGMGeometry(height, width, x0, x1)
