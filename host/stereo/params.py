"""Block-matching parameters and the frame geometry they imply.

The limits are the protocol's parameter table and SPEC §5.2 rules (which mirror
``StereoBMImpl::compute`` in OpenCV, modules/stereo/src/stereobm.cpp); the geometry mirrors
``findStereoCorrespondenceBM`` and ``getValidDisparityROI``.
"""
from __future__ import annotations

from dataclasses import dataclass

from stereocam.protocol.frame_messages import invalid_disparity
from stereocam.protocol.params import Algorithm

from .config_map import ConfigField, ValueName, check_params, check_rule

BM_CONFIG: tuple[ConfigField, ...] = (
    ConfigField("num_disparities"), ConfigField("block_size"), ConfigField("min_disparity"),
    ConfigField("pre_filter_type", transform=ValueName("pre_filter_type")),
    ConfigField("pre_filter_size"), ConfigField("pre_filter_cap"), ConfigField("texture_threshold"),
    ConfigField("uniqueness_ratio"), ConfigField("speckle_window_size"), ConfigField("speckle_range"),
    ConfigField("disp12_max_diff"),
)
"""Device configuration key -> MatchParams field; the limits are the protocol's."""


@dataclass(frozen=True)
class MatchParams:
    """StereoBM parameters (OpenCV names in brackets), OpenCV defaults."""

    num_disparities: int = 64  # numDisparities
    block_size: int = 21  # blockSize (SADWindowSize)
    min_disparity: int = 0  # minDisparity
    pre_filter_type: str = "xsobel"  # PREFILTER_XSOBEL or "normalized" (NORMALIZED_RESPONSE)
    pre_filter_size: int = 9  # preFilterSize
    pre_filter_cap: int = 31  # preFilterCap
    texture_threshold: int = 10  # textureThreshold
    uniqueness_ratio: int = 15  # uniquenessRatio
    speckle_window_size: int = 0  # speckleWindowSize
    speckle_range: int = 0  # speckleRange (1/16 px units for BM, as OpenCV passes it)
    disp12_max_diff: int = -1  # disp12MaxDiff (< 0: left-right check off)

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """ConfigError (a ValueError) naming the first parameter the protocol's table refuses."""
        check_params(self, BM_CONFIG)

    @property
    def invalid_value(self) -> int:
        """Value written for pixels without a disparity: (min_disparity - 1) * 16."""
        return invalid_disparity(self.min_disparity)

    @property
    def use_speckle(self) -> bool:
        return self.speckle_range >= 0 and self.speckle_window_size > 0

    @property
    def max_sad(self) -> int:
        """Upper bound of a window SAD (decides 16- or 32-bit accumulators)."""
        return 2 * self.pre_filter_cap * self.block_size * self.block_size


@dataclass(frozen=True)
class Geometry:
    """Column/row ranges of one (height, width, params) combination, OpenCV's names."""

    height: int
    width: int
    lofs: int  # first column the SAD loop computes
    rofs: int  # right-image column offset (min_disparity + N - 1 < 0)
    width1: int  # number of columns the SAD loop computes
    roi_x0: int  # valid region (getValidDisparityROI), columns [roi_x0, roi_x1)
    roi_x1: int
    roi_y0: int  # rows [roi_y0, roi_y1)
    roi_y1: int
    lr_x0: int  # columns validateDisparity scans, [lr_x0, lr_x1)
    lr_x1: int


def geometry(height: int, width: int, p: MatchParams) -> Geometry:
    """Derive the computed/valid ranges; ConfigError (the protocol's SPEC §5.2 rules) when no valid
    pixel can exist."""
    nd, md, r = p.num_disparities, p.min_disparity, p.block_size // 2
    frame = {"width": width, "height": height, "algorithm": Algorithm.BLOCK_MATCHING,
             "block_size": p.block_size, "min_disparity": md, "num_disparities": nd}
    check_rule("block_size_vs_image", frame)
    check_rule("disparity_range_vs_width", frame)
    lofs = max(nd - 1 + md, 0)
    rofs = -min(nd - 1 + md, 0)
    width1 = width - rofs - nd + 1
    max_d = md + nd - 1
    roi_x0, roi_x1 = max(0, max_d) + r, width - r
    roi_y0, roi_y1 = r, height - r
    return Geometry(height, width, lofs, rofs, width1, roi_x0, roi_x1, roi_y0, roi_y1,
                    max(md + nd, 0), width + min(md, 0))
