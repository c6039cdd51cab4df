"""Semi-global matching parameters and the frame geometry they imply.

The algorithm (census cost, path aggregation, winner-take-all, uniqueness, subpixel, left-right
check) is specified once, in plain numpy, by tests/sgm_reference.py; the numba engine is
bit-exact with it.
"""
from __future__ import annotations

from dataclasses import dataclass
from numbers import Integral

from stereocam.protocol.errors import ConfigError
from stereocam.protocol.frame_messages import invalid_disparity
from stereocam.protocol.params import BY_NAME, Algorithm

from .config_map import ConfigField, check_params, check_rule

PATH_COST_LIMIT = 255  # path costs L <= census bits + p2 are held in uint8
CENSUS_BITS = 64  # census codes are uint64
PATH_COUNTS = BY_NAME["sgm_paths"].one_of  # path directions the engine aggregates (sgm_reference.PATHS)
MARGIN_DIVISOR = 10  # automatic census margin: median |3x3 Laplacian| // this (~0.4 noise sigma)
MARGIN_MAX = 255

SGM_CONFIG: tuple[ConfigField, ...] = (
    ConfigField("num_disparities"), ConfigField("min_disparity"),
    ConfigField("census_width", protocol_limits=False), ConfigField("census_height", protocol_limits=False),
    ConfigField("sgm_paths", "paths", protocol_limits=False), ConfigField("sgm_p1", "p1"),
    ConfigField("sgm_p2", "p2", protocol_limits=False), ConfigField("sgm_p2_adapt", "p2_adapt", protocol_limits=False),
    ConfigField("uniqueness_ratio"), ConfigField("disp12_max_diff", "lr_max_diff"),
    ConfigField("speckle_window_size"), ConfigField("speckle_range"),
)
"""Device configuration key -> SGMParams field. The census window and p2 have the engine's own
(wider) limits: any census window of up to 64 comparisons, p2 up to what uint8 path costs hold;
and the path count (4, 5 or 8); the protocol's ranges lie within them."""


def census_neighbours(cw: int, ch: int, sparse: bool) -> list[tuple[int, int]]:
    """(dy, dx) of the census comparisons of a cw x ch window (odd sides), row by row, the
    centre skipped; sparse: only those with |dx| + |dy| odd."""
    rx, ry = cw // 2, ch // 2
    return [(dy, dx) for dy in range(-ry, ry + 1) for dx in range(-rx, rx + 1)
            if (dy, dx) != (0, 0) and (not sparse or (dx + dy) % 2 == 1)]


def _default(name: str) -> int:
    """The protocol's default for an SGM row: the engine's own default is the device's."""
    return int(BY_NAME[name].default)


P2_ADAPT_MAX = 1 << 20  # beyond it P2 / (1 + |dI| / p2_adapt) is P2 anyway; p2 * p2_adapt fits int64


@dataclass(frozen=True)
class SGMParams:
    """SGM parameters; the defaults are a good general setting (census 9x7, 5 paths in one pass per
    image half: as accurate as 8 on the bench's scenes at about half the time)."""

    num_disparities: int = 128  # disparities min_disparity .. min_disparity + N - 1
    min_disparity: int = 0
    census_width: int = _default("census_width")  # census window (odd sides, at most 64 comparisons)
    census_height: int = _default("census_height")
    census_sparse: bool = True  # compare the centre with the neighbours an odd number of steps
    # away only (|dx| + |dy| odd: 32 of a 9x7 window's 62): half the census bits, matched in
    # about 10 % less time; at the same p1 / p2 bad-2.0 as low or lower on the bench's scenes
    # but noise (README)
    census_margin: int = -1  # census bits only where the 3x3-smoothed neighbour and centre differ
    # by more than this many DN (flat, noisy areas get a flat cost); -1: from each image's noise
    # (census.noise_margin), 0: plain census
    paths: int = _default("sgm_paths")  # 5 (one pass per image half from its outer edge: horizontal,
    # vertical and the two diagonals from that edge), 4 (horizontal + vertical) or 8 (every direction)
    p1: int = _default("sgm_p1")  # penalty for a 1 px disparity change between path neighbours
    p2: int = _default("sgm_p2")  # penalty for a larger change (25 / 190 chosen for the dense
    # census: bad-2.0 lower on Motorcycle and every scene class than 15 / 128; with the sparse one
    # lower than the dense one's on every class but noise, 6.9 -> 7.1 %)
    p2_adapt: int = _default("sgm_p2_adapt")  # > 0: P2 / (1 + |dI| / p2_adapt) along the path, not
    # below p1 (nor above p2); 0: off
    p1_ground_percent: int = 50  # on the vertical and diagonal paths in the lower half of the
    # image (rows from ceil(h / 2)) a 1 px step the way a floor's disparity goes (growing
    # downwards) costs this percent of p1 (p1_ground_step): the paths no longer lag behind a
    # road's disparity (bad-2.0 on the driving class 27.8 -> 20.5 % with 5 paths, no class
    # worse); 100: off
    uniqueness_ratio: int = 0  # percent margin the best cost must keep over others (0: off)
    lr_max_diff: int = -1  # left-right check tolerance in px (< 0: off)
    speckle_window_size: int = 100  # regions of at most this many pixels are removed (0: off)
    speckle_range: int = 32  # 1/16 px: neighbours differing by more start a new region

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """ConfigError (a ValueError) naming the first invalid parameter: the protocol's limits, then
        the engine's own for the census window and p2."""
        check_params(self, SGM_CONFIG)
        cw, ch = self.census_width, self.census_height
        if not isinstance(self.census_sparse, bool):
            raise ConfigError(f"census_sparse must be True or False, got {self.census_sparse!r}")
        if cw < 1 or ch < 1 or cw % 2 == 0 or ch % 2 == 0 or not 1 <= self.max_cost <= CENSUS_BITS:
            raise ConfigError(f"census window must be odd by odd with 1..{CENSUS_BITS} comparisons"
                              f"{' (sparse: the neighbours an odd number of steps away)' if self.census_sparse else ''}"
                              f", got {cw}x{ch}")
        if self.paths not in PATH_COUNTS:
            raise ConfigError(f"paths must be one of {', '.join(map(str, PATH_COUNTS))}, got {self.paths}")
        if self.p2 < 0 or self.max_cost + self.p2 > PATH_COST_LIMIT:
            raise ConfigError(f"p2 {self.p2} out of range: 0 <= p2 and census bits {self.max_cost} + p2 "
                              f"<= {PATH_COST_LIMIT}")
        if isinstance(self.census_margin, bool) or not isinstance(self.census_margin, int) \
                or not -1 <= self.census_margin <= MARGIN_MAX:
            raise ConfigError(f"census_margin must be -1 (from the image's noise) or 0..{MARGIN_MAX}, "
                              f"got {self.census_margin}")
        if isinstance(self.p2_adapt, bool) or not isinstance(self.p2_adapt, Integral) \
                or not 0 <= self.p2_adapt <= P2_ADAPT_MAX:
            raise ConfigError(f"p2_adapt must be 0..{P2_ADAPT_MAX}, got {self.p2_adapt}")
        if isinstance(self.p1_ground_percent, bool) or not isinstance(self.p1_ground_percent, int) \
                or not 0 <= self.p1_ground_percent <= 100:
            raise ConfigError(f"p1_ground_percent must be 0..100, got {self.p1_ground_percent}")

    @property
    def max_cost(self) -> int:
        """Largest matching cost: the number of census comparison bits."""
        cw, ch = self.census_width, self.census_height
        if not self.census_sparse:
            return cw * ch - 1
        ex, ey = cw // 4 * 2 + 1, ch // 4 * 2 + 1  # even offsets -r..r of an odd side (r = side // 2)
        return ex * (ch - ey) + (cw - ex) * ey  # |dx| + |dy| odd: one of them odd (census_neighbours)

    @property
    def outside_cost(self) -> int:
        """Cost of a disparity whose right pixel is left of the image: 3/8 of the census bits
        (rounded down), about what a wrong match costs, so the paths carry the scene into the left
        band. The largest cost (all bits) pushed the band toward small disparities: with it, mean
        bad-2.0 over Motorcycle and every scene class (seeds 3 and 5) was 13.56 % against 11.61 %
        (Motorcycle 11.64 -> 8.64; the columns past the band 11.72 -> 11.49)."""
        return self.max_cost * 3 // 8

    @property
    def p1_ground_step(self) -> int:
        """P1 of the ground's step on the vertical and diagonal paths."""
        return self.p1 * self.p1_ground_percent // 100

    @property
    def invalid_value(self) -> int:
        """Value written for pixels without a disparity: (min_disparity - 1) * 16."""
        return invalid_disparity(self.min_disparity)

    @property
    def use_speckle(self) -> bool:
        return self.speckle_window_size > 0


@dataclass(frozen=True)
class SGMGeometry:
    """Columns [x0, x1) that are matched (the path rectangle): those where the smallest
    disparity has its right pixel in the image and, on the right, every disparity does; the
    rest of each row is invalid. Near the left edge the larger disparities point left of the
    right image; their cost is the largest (census bits) and the paths carry the scene in."""

    height: int
    width: int
    x0: int
    x1: int

    @property
    def cols(self) -> int:
        return self.x1 - self.x0


def sgm_geometry(height: int, width: int, p: SGMParams) -> SGMGeometry:
    """The matched column range; ConfigError (the protocol's SPEC §5.2 rule) when the image cannot hold one."""
    if height < 1:
        raise ConfigError(f"image {width}x{height} has no rows")
    check_rule("sgm_disparity_range_vs_width", {"width": width, "algorithm": Algorithm.SEMI_GLOBAL,
                                                "min_disparity": p.min_disparity, "num_disparities": p.num_disparities})
    x0 = max(p.min_disparity, 0)
    x1 = min(width, width + p.min_disparity)
    return SGMGeometry(height, width, x0, x1)
