"""How the viewer lays out the camera's settings: which group each belongs to (by name, then by
name prefix, else ``OTHER``), the unit as people write it, and the named choices of a setting
(from the parameter table's ``values``; ``outputs`` as the ``Output`` planes it switches)."""
from __future__ import annotations

from dataclasses import asdict
from typing import Any

from stereocam.protocol.params import Output, Param

GROUPS = ("capture", "matching", "post-processing", "trigger", "link")
OTHER = "other"
_BY_NAME = {
    "width": "capture", "height": "capture", "fps": "capture", "exposure_us": "capture", "gain": "capture",
    "outputs": "capture", "rectify": "capture", "rectified_fov": "capture",
    "algorithm": "matching", "num_disparities": "matching", "block_size": "matching", "min_disparity": "matching",
    "texture_threshold": "matching", "uniqueness_ratio": "matching",
    "speckle_window_size": "post-processing", "speckle_range": "post-processing",
    "disp12_max_diff": "post-processing", "lr_check": "post-processing", "hole_fill": "post-processing",
    "median_size": "post-processing", "decimation": "post-processing",
    "trigger_mode": "trigger", "trigger_output": "trigger",
    "heartbeat_timeout_ms": "link",
}
_BY_PREFIX = (("pre_filter_", "matching"), ("sgm_", "matching"), ("census_", "matching"),
              ("spatial_", "post-processing"), ("temporal_", "post-processing"), ("speckle_", "post-processing"),
              ("trigger_", "trigger"))
UNITS = {"us": "µs", "Hz": "fps"}  # the table's unit -> as written on the page


def group_of(name: str) -> str:
    """The page's group for a setting: by its name, then by a name prefix, else ``OTHER``."""
    if name in _BY_NAME:
        return _BY_NAME[name]
    return next((group for prefix, group in _BY_PREFIX if name.startswith(prefix)), OTHER)


def choices(param: Param) -> dict[str, Any] | None:
    """A setting's named values: {"kind": "menu", "values": {value: name}} for an enumerated one,
    {"kind": "flags", ...} for ``outputs`` (a bit per plane); None for a plain number."""
    if param.values:
        return {"kind": "menu", "values": {str(int(v)): name for v, name in param.values.items()}}
    if param.name == "outputs":
        return {"kind": "flags", "values": {str(int(f)): str(f.name).lower() for f in Output}}
    return None


def describe(param: Param, value: int | None) -> dict[str, Any]:
    """One setting as the page shows it: the table's row, its group, unit label, choices and value."""
    row = {k: v for k, v in asdict(param).items() if k != "values"}
    return {**row, "value": value, "group": group_of(param.name), "unit": UNITS.get(param.unit, param.unit),
            "choices": choices(param)}
