"""The configuration parameter table: wire id, name, range, default (protocol/SPEC.md §5).

Every parameter is an int32 on the wire. The device validates against this table; the host uses it
to map names to ids. One table, shared by both sides.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, replace


class TriggerMode(enum.IntEnum):
    FREE_RUN = 0
    SOFTWARE = 1
    EXTERNAL = 2


class Output(enum.IntFlag):
    """Planes a frame can carry; also the plane ids of FRAME_DATA."""

    LEFT = 1
    RIGHT = 2
    DISPARITY = 4


@dataclass(frozen=True)
class Param:
    pid: int
    name: str
    default: int
    lo: int
    hi: int
    step: int = 1  # value must be lo + k*step ... or: see ``odd``
    odd: bool = False
    unit: str = ""
    live: bool = True  # may change while streaming
    description: str = ""  # one line for humans (Camera.options(), help texts, the viewer)

    def check(self, value: int) -> str | None:
        """None if ``value`` is acceptable on its own, else the reason."""
        if not self.lo <= value <= self.hi:
            return f"{self.name}={value} outside {self.lo}..{self.hi}"
        if self.odd and value % 2 == 0:
            return f"{self.name}={value} must be odd"
        if self.step > 1 and value % self.step:
            return f"{self.name}={value} must be a multiple of {self.step}"
        return None


PARAMS: tuple[Param, ...] = (
    Param(1, "width", 640, 64, 1280, step=16, unit="px", live=False),
    Param(2, "height", 480, 48, 960, step=8, unit="px", live=False),
    Param(3, "fps", 30, 1, 120, unit="Hz"),
    Param(4, "exposure_us", 4000, 10, 1_000_000, unit="us"),
    Param(5, "gain", 0, 0, 240, unit="0.1 dB"),
    Param(6, "trigger_mode", TriggerMode.FREE_RUN, 0, 2, live=False),
    Param(7, "outputs", Output.LEFT | Output.RIGHT | Output.DISPARITY, 1, 7),
    Param(8, "num_disparities", 64, 16, 256, step=16, unit="px"),
    Param(9, "block_size", 15, 5, 255, odd=True, unit="px"),
    Param(10, "min_disparity", 0, -256, 256, unit="px"),
    Param(11, "pre_filter_type", 0, 0, 1),  # 0 xsobel, 1 normalized response
    Param(12, "pre_filter_size", 9, 5, 255, odd=True, unit="px"),
    Param(13, "pre_filter_cap", 31, 1, 63),
    Param(14, "texture_threshold", 10, 0, 1 << 20),
    Param(15, "uniqueness_ratio", 15, 0, 100, unit="%"),
    Param(16, "speckle_window_size", 0, 0, 10_000, unit="px"),
    Param(17, "speckle_range", 0, 0, 1 << 14, unit="1/16 px"),
    Param(18, "disp12_max_diff", -1, -1, 1 << 14, unit="px"),
    Param(19, "heartbeat_timeout_ms", 3000, 0, 600_000, unit="ms"),  # 0: never time out
    # id 20 is retired (a simulator control in drafts of 1.1); never reused
    Param(21, "rectify", 1, 0, 1),  # 1: rectified images + disparity; 0: raw images (INFO RAW_OUTPUT)
    # matching algorithm and the semi-global matcher's own parameters (SGM also uses 8, 10, 15..18)
    Param(22, "algorithm", 0, 0, 1),  # 0 block matching (StereoBM), 1 semi-global matching
    Param(23, "sgm_p1", 15, 0, 255),  # SGM penalty for a 1 px disparity step along a path
    Param(24, "sgm_p2", 128, 0, 193),  # SGM penalty for larger steps (census bits + p2 <= 255)
    Param(25, "sgm_p2_adapt", 32, 0, 255),  # > 0: p2 / (1 + |dI| / this), not below p1; 0 off
    Param(26, "sgm_paths", 8, 4, 8, step=4),  # 4 (horizontal + vertical) or 8 (+ diagonals)
    Param(27, "census_width", 9, 3, 9, odd=True, unit="px"),  # SGM census window
    Param(28, "census_height", 7, 1, 7, odd=True, unit="px"),
    # 1: this unit drives the trigger line at fps (INFO TRIGGER_OUTPUT)
    Param(29, "trigger_output", 0, 0, 1, live=False),
)

DESCRIPTIONS: dict[str, str] = {
    "width": "image width after binning/cropping",
    "height": "image height after binning/cropping",
    "fps": "frame rate in free-run mode",
    "exposure_us": "exposure time of both imagers",
    "gain": "analogue gain of both imagers",
    "trigger_mode": "0 free run, 1 software trigger (trigger()), 2 external trigger input",
    "outputs": "planes each frame carries: 1 left + 2 right + 4 disparity",
    "num_disparities": "disparity search range (max - min disparity)",
    "block_size": "matching window side (odd)",
    "min_disparity": "smallest disparity searched",
    "pre_filter_type": "0 x-Sobel, 1 normalized response",
    "pre_filter_size": "pre-filter window side (odd), normalized response only",
    "pre_filter_cap": "clip of the pre-filtered image",
    "texture_threshold": "minimum texture in the window for a match to count",
    "uniqueness_ratio": "margin the best match must beat the second best by",
    "speckle_window_size": "largest speckle region removed (0: off)",
    "speckle_range": "disparity step that splits speckle regions",
    "disp12_max_diff": "left-right consistency tolerance (-1: off)",
    "heartbeat_timeout_ms": "the device stops streaming after this long without a host message (0: never)",
    "rectify": "1 rectified images + disparity, 0 raw images without disparity (INFO RAW_OUTPUT)",
    "algorithm": "0 block matching, 1 semi-global matching (census + SGM)",
    "sgm_p1": "SGM penalty for a 1 px disparity step along a path",
    "sgm_p2": "SGM penalty for larger disparity steps",
    "sgm_p2_adapt": "SGM: p2 / (1 + |intensity step| / this), not below p1 (0: off)",
    "sgm_paths": "SGM aggregation paths: 4 or 8",
    "census_width": "SGM census window width (odd)",
    "census_height": "SGM census window height (odd)",
    "trigger_output": "1: this unit is the trigger master, pulsing the line at fps while streaming (external mode)",
}
PARAMS = tuple(replace(p, description=DESCRIPTIONS.get(p.name, p.description)) for p in PARAMS)

BY_ID: dict[int, Param] = {p.pid: p for p in PARAMS}
BY_NAME: dict[str, Param] = {p.name: p for p in PARAMS}

VALUE_NAMES: dict[str, dict[int, str]] = {  # enumerated parameters: value -> name (outputs is a bit set)
    "trigger_mode": {int(t): t.name.lower() for t in TriggerMode},
    "pre_filter_type": {0: "xsobel", 1: "normalized"},
    "rectify": {0: "raw", 1: "rectified"},
    "algorithm": {0: "block_matching", 1: "sgm"},
    "trigger_output": {0: "off", 1: "master"},
}


def defaults() -> dict[str, int]:
    return {p.name: int(p.default) for p in PARAMS}
