"""The configuration parameter table: wire id, name, range, default (protocol/SPEC.md §5).

Every parameter is an int32 on the wire. The device validates against this table; the host uses it
to map names to ids. One table, shared by both sides.
"""
from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field


class TriggerMode(enum.IntEnum):
    FREE_RUN = 0
    SOFTWARE = 1
    EXTERNAL = 2


class Algorithm(enum.IntEnum):
    """Values of the ``algorithm`` parameter: the matching engine a configuration selects (SPEC §5.1)."""

    BLOCK_MATCHING = 0  # StereoBM semantics
    SEMI_GLOBAL = 1  # census + semi-global matching


class Output(enum.IntFlag):
    """Planes a frame can carry; also the plane ids of FRAME_DATA."""

    LEFT = 1
    RIGHT = 2
    DISPARITY = 4
    CONFIDENCE = 8  # since 1.3 (INFO POST_PROCESSING): uint8 per pixel, SPEC §5.3


@dataclass(frozen=True)
class Param:
    pid: int
    name: str
    default: int
    lo: int
    hi: int
    step: int = 1  # value must be lo + k*step ... or: see ``odd``
    odd: bool = False
    one_of: tuple[int, ...] = ()  # when set, the only values accepted within lo..hi
    unit: str = ""
    live: bool = True  # may change while streaming
    description: str = ""  # one line for humans (Camera.options(), help texts, the viewer)
    values: Mapping[int, str] = field(default_factory=dict, compare=False)  # enumerated values -> names

    def check(self, value: int) -> str | None:
        """None if ``value`` is acceptable on its own, else the reason."""
        if not self.lo <= value <= self.hi:
            return f"{self.name}={value} outside {self.lo}..{self.hi}"
        if self.odd and value % 2 == 0:
            return f"{self.name}={value} must be odd"
        if self.step > 1 and value % self.step:
            return f"{self.name}={value} must be a multiple of {self.step}"
        if self.one_of and value not in self.one_of:
            return f"{self.name}={value} must be one of {', '.join(map(str, self.one_of))}"
        return None


INT32_MIN, INT32_MAX = -(1 << 31), (1 << 31) - 1
"""Every parameter value is an int32 on the wire (SPEC §5); every range below lies inside it."""

_TRIGGER_MODES = {int(t): t.name.lower() for t in TriggerMode}

PARAMS: tuple[Param, ...] = (
    Param(1, "width", 640, 64, 1280, step=16, unit="px", live=False,
          description="image width after binning/cropping"),
    Param(2, "height", 480, 48, 960, step=8, unit="px", live=False,
          description="image height after binning/cropping"),
    Param(3, "fps", 30, 1, 120, unit="Hz", description="frame rate in free-run mode"),
    Param(4, "exposure_us", 4000, 10, 1_000_000, unit="us", description="exposure time of both imagers"),
    Param(5, "gain", 0, 0, 240, unit="0.1 dB", description="analogue gain of both imagers"),
    Param(6, "trigger_mode", TriggerMode.FREE_RUN, 0, 2, live=False, values=_TRIGGER_MODES,
          description="0 free run, 1 software trigger (trigger()), 2 external trigger input"),
    Param(7, "outputs", Output.LEFT | Output.RIGHT | Output.DISPARITY, 1, 15,
          description="planes each frame carries: 1 left + 2 right + 4 disparity + 8 confidence"),
    Param(8, "num_disparities", 64, 16, 256, step=16, unit="px",
          description="disparity search range (max - min disparity)"),
    Param(9, "block_size", 15, 5, 255, odd=True, unit="px", description="matching window side (odd)"),
    Param(10, "min_disparity", 0, -256, 256, unit="px", description="smallest disparity searched"),
    Param(11, "pre_filter_type", 0, 0, 1, values={0: "xsobel", 1: "normalized"},
          description="0 x-Sobel, 1 normalized response"),
    Param(12, "pre_filter_size", 9, 5, 255, odd=True, unit="px",
          description="pre-filter window side (odd), normalized response only"),
    Param(13, "pre_filter_cap", 31, 1, 63, description="clip of the pre-filtered image"),
    Param(14, "texture_threshold", 10, 0, 1 << 20, description="minimum texture in the window for a match to count"),
    Param(15, "uniqueness_ratio", 15, 0, 100, unit="%",
          description="margin the best match must beat the second best by"),
    Param(16, "speckle_window_size", 0, 0, 10_000, unit="px", description="largest speckle region removed (0: off)"),
    Param(17, "speckle_range", 0, 0, 1 << 14, unit="1/16 px", description="disparity step that splits speckle regions"),
    Param(18, "disp12_max_diff", -1, -1, 1 << 14, unit="px", description="left-right consistency tolerance (-1: off)"),
    Param(19, "heartbeat_timeout_ms", 3000, 0, 600_000, unit="ms",
          description="the device stops streaming after this long without a host message (0: never)"),
    # id 20 is retired (a simulator control in drafts of 1.1); never reused
    Param(21, "rectify", 1, 0, 1, values={0: "raw", 1: "rectified"},
          description="1 rectified images + disparity, 0 raw images without disparity (INFO RAW_OUTPUT)"),
    # matching algorithm and the semi-global matcher's own parameters (SGM also uses 8, 10, 15..18)
    Param(22, "algorithm", Algorithm.BLOCK_MATCHING, min(Algorithm), max(Algorithm),
          values={Algorithm.BLOCK_MATCHING: "block_matching", Algorithm.SEMI_GLOBAL: "sgm"},
          description="0 block matching, 1 semi-global matching (census + SGM)"),
    Param(23, "sgm_p1", 25, 0, 255, description="SGM penalty for a 1 px disparity step along a path"),
    Param(24, "sgm_p2", 190, 0, 193,  # census bits + p2 <= 255
          description="SGM penalty for larger disparity steps"),
    Param(25, "sgm_p2_adapt", 32, 0, 255,
          description="SGM: p2 / (1 + |intensity step| / this), not below p1 (0: off)"),
    Param(26, "sgm_paths", 5, 4, 8, one_of=(4, 5, 8),
          description="SGM aggregation paths: 4, 5 (one pass per image half) or 8"),
    Param(27, "census_width", 9, 3, 9, odd=True, unit="px", description="SGM census window width (odd)"),
    Param(28, "census_height", 7, 1, 7, odd=True, unit="px", description="SGM census window height (odd)"),
    Param(29, "trigger_output", 0, 0, 1, live=False, values={0: "off", 1: "master"},
          description="1: this unit is the trigger master, pulsing the line at fps while streaming (external mode)"),
    # post-processing after the engine, in this order (SPEC §5.3; INFO POST_PROCESSING); 0 turns a stage off
    Param(30, "lr_check", -1, -1, 64, unit="px",
          description="left-right check against the mirrored pair's disparity: tolerance (-1: off)"),
    Param(31, "hole_fill", 0, 0, 2, values={0: "off", 1: "nearest", 2: "background"},
          description="fill invalid pixels: 1 nearest valid in the row, 2 background along 8 paths"),
    Param(32, "spatial_alpha", 0, 0, 256, unit="1/256",
          description="edge-preserving (domain transform) filter: weight of the current pixel (0: off)"),
    Param(33, "spatial_delta", 32, 1, 1 << 12, unit="1/16 px",
          description="spatial filter: neighbours differing by more are an edge, not smoothed"),
    Param(34, "spatial_iterations", 2, 1, 5, description="spatial filter: passes (each left, right, down, up)"),
    Param(35, "temporal_alpha", 0, 0, 256, unit="1/256",
          description="temporal filter: weight of the new frame (0: off)"),
    Param(36, "temporal_delta", 32, 1, 1 << 12, unit="1/16 px",
          description="temporal filter: a pixel changing by more starts afresh"),
    Param(37, "temporal_persistence", 0, 0, 8, unit="frames",
          description="temporal filter: an invalid pixel keeps the last value up to this many frames (0: off)"),
    Param(38, "median_size", 1, 1, 5, odd=True, unit="px", description="median filter window side: 3 or 5 (1: off)"),
    Param(39, "decimation", 1, 1, 4, unit="px",
          description="median of the valid pixels of each n x n block, written to the whole block (1: off)"),
    Param(40, "rectified_fov", 120, 30, 170, unit="deg",
          description="equidistant (fisheye) lenses: field of view across the width of the rectified images"),
)

BY_ID: dict[int, Param] = {p.pid: p for p in PARAMS}
BY_NAME: dict[str, Param] = {p.name: p for p in PARAMS}

VALUE_NAMES: dict[str, Mapping[int, str]] = {p.name: p.values for p in PARAMS if p.values}
"""Enumerated parameters: value -> name (a view of the rows' ``values``; outputs is a bit set)."""


def defaults() -> dict[str, int]:
    return {p.name: int(p.default) for p in PARAMS}
