"""Block-matching parameters and the frame geometry they imply.

The checks mirror ``StereoBMImpl::compute`` in OpenCV (modules/stereo/src/stereobm.cpp); the
geometry mirrors ``findStereoCorrespondenceBM`` and ``getValidDisparityROI``.
"""
from __future__ import annotations

from dataclasses import dataclass

PREFILTER_TYPES = ("xsobel", "normalized")
DISP_SHIFT = 4  # output is disparity * 16


def _check_int(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"{name} must be an int, got {value!r}")
    return value


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
        """Raise ValueError naming the first invalid parameter."""
        for name in ("num_disparities", "block_size", "min_disparity", "pre_filter_size",
                     "pre_filter_cap", "texture_threshold", "uniqueness_ratio",
                     "speckle_window_size", "speckle_range", "disp12_max_diff"):
            _check_int(name, getattr(self, name))
        if self.pre_filter_type not in PREFILTER_TYPES:
            raise ValueError(f"pre_filter_type must be one of {PREFILTER_TYPES}, "
                             f"got {self.pre_filter_type!r}")
        ps = self.pre_filter_size
        if ps < 5 or ps > 255 or ps % 2 == 0:
            raise ValueError(f"pre_filter_size must be odd and within 5..255, got {ps}")
        if not 1 <= self.pre_filter_cap <= 63:
            raise ValueError(f"pre_filter_cap must be within 1..63, got {self.pre_filter_cap}")
        bs = self.block_size
        if bs < 5 or bs > 255 or bs % 2 == 0:
            raise ValueError(f"block_size must be odd and within 5..255, got {bs}")
        nd = self.num_disparities
        if nd <= 0 or nd % 16 != 0:
            raise ValueError(f"num_disparities must be positive and divisible by 16, got {nd}")
        if self.texture_threshold < 0:
            raise ValueError(f"texture_threshold must be non-negative, "
                             f"got {self.texture_threshold}")
        if self.uniqueness_ratio < 0:
            raise ValueError(f"uniqueness_ratio must be non-negative, got {self.uniqueness_ratio}")
        if self.speckle_window_size < 0:
            raise ValueError(f"speckle_window_size must be non-negative, "
                             f"got {self.speckle_window_size}")
        if self.speckle_range < 0:
            raise ValueError(f"speckle_range must be non-negative, got {self.speckle_range}")
        # |min_disparity| and the disparity range must keep (d * 16) inside int16.
        lo, hi = (self.min_disparity - 1) * 16, (self.min_disparity + nd) * 16
        if lo < -32768 or hi > 32767:
            raise ValueError(f"min_disparity {self.min_disparity} with num_disparities {nd} "
                             "does not fit the int16 output")

    @property
    def invalid_value(self) -> int:
        """Value written for pixels without a disparity: (min_disparity - 1) * 16."""
        return (self.min_disparity - 1) << DISP_SHIFT

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
    """Derive the computed/valid ranges; ValueError when no valid pixel can exist."""
    nd, md, r = p.num_disparities, p.min_disparity, p.block_size // 2
    if p.block_size >= min(width, height):
        raise ValueError(f"block_size {p.block_size} must be smaller than the image width "
                         f"and height ({width}x{height})")
    lofs = max(nd - 1 + md, 0)
    rofs = -min(nd - 1 + md, 0)
    width1 = width - rofs - nd + 1
    max_d = md + nd - 1
    roi_x0, roi_x1 = max(0, max_d) + r, width - r
    roi_y0, roi_y1 = r, height - r
    if lofs >= width or rofs >= width or width1 < 1 or roi_x1 <= roi_x0:
        raise ValueError(
            f"image width {width} is too small for num_disparities {nd}, min_disparity {md} "
            f"and block_size {p.block_size}: no column can hold a valid disparity")
    return Geometry(height, width, lofs, rofs, width1, roi_x0, roi_x1, roi_y0, roi_y1,
                    max(md + nd, 0), width + min(md, 0))
