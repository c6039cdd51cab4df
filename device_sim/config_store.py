"""The device's configuration store: validated, all-or-nothing updates."""
from __future__ import annotations

import threading
from dataclasses import dataclass

from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.params import BY_ID, BY_NAME, PARAMS, TriggerMode, defaults


@dataclass(frozen=True)
class Rejection:
    """Why an update was refused; the store is unchanged."""

    code: ErrorCode
    param_id: int
    message: str


class ConfigStore:
    """Current configuration by name; ``apply`` checks a whole update before changing anything."""

    def __init__(self) -> None:
        self._values = defaults()
        self._lock = threading.Lock()

    def snapshot(self) -> dict[str, int]:
        with self._lock:
            return dict(self._values)

    def by_id(self) -> dict[int, int]:
        snap = self.snapshot()
        return {p.pid: snap[p.name] for p in PARAMS}

    def apply(self, update: dict[int, int], streaming: bool) -> Rejection | None:
        """Apply ``update`` (wire id → value) atomically; a Rejection leaves the store as it was."""
        with self._lock:
            new = dict(self._values)
            for pid, value in update.items():
                p = BY_ID.get(pid)
                if p is None:
                    return Rejection(ErrorCode.UNKNOWN_PARAM, pid, f"unknown parameter id {pid}")
                why = p.check(value)
                if why:
                    return Rejection(ErrorCode.OUT_OF_RANGE, pid, why)
                if streaming and not p.live and value != new[p.name]:
                    return Rejection(ErrorCode.BAD_STATE, pid, f"{p.name} cannot change while streaming; stop first")
                new[p.name] = value
            rej = _cross_check(new, update)
            if rej:
                return rej
            self._values = new
            return None


def _cross_check(c: dict[str, int], update: dict[int, int]) -> Rejection | None:
    """Constraints between parameters; blame the parameter the update touched."""
    def blame(*names: str) -> int:
        for n in names:
            if BY_NAME[n].pid in update:
                return BY_NAME[n].pid
        return BY_NAME[names[0]].pid

    if c["block_size"] > min(c["width"], c["height"]):
        return Rejection(ErrorCode.OUT_OF_RANGE, blame("block_size", "width", "height"),
                         f"block_size={c['block_size']} larger than the image {c['width']}x{c['height']}")
    if c["pre_filter_size"] > min(c["width"], c["height"]):
        return Rejection(ErrorCode.OUT_OF_RANGE, blame("pre_filter_size", "width", "height"),
                         f"pre_filter_size={c['pre_filter_size']} larger than the image")
    span = c["min_disparity"] + c["num_disparities"] + c["block_size"] // 2
    if span >= c["width"] or -c["min_disparity"] >= c["width"]:
        return Rejection(ErrorCode.OUT_OF_RANGE, blame("num_disparities", "min_disparity", "width"),
                         f"disparity range {c['min_disparity']}..{c['min_disparity'] + c['num_disparities']}"
                         f" does not fit in width {c['width']}")
    if c["trigger_mode"] == TriggerMode.FREE_RUN and c["exposure_us"] > 1_000_000 // c["fps"]:
        return Rejection(ErrorCode.OUT_OF_RANGE, blame("exposure_us", "fps"),
                         f"exposure_us={c['exposure_us']} longer than the frame period at fps={c['fps']}")
    return None
