"""Which configurations a device accepts (SPEC §4.3 steps 2–3, §5.2): one rule set for both sides.

The device's config store applies an update with ``merge``; the host checks a would-be
configuration with it before sending (``Camera.check_config``). The device stays the authority:
the host check only spares a round trip and names the parameter earlier.
"""
from __future__ import annotations

from collections.abc import Mapping

from .errors import ConfigError, ErrorCode
from .params import BY_ID, BY_NAME, TriggerMode


class ConfigRejected(ConfigError):
    """A configuration the device refuses: the NACK code it sends, the parameter it names, why."""

    def __init__(self, code: ErrorCode, param_id: int, message: str):
        super().__init__(message)
        self.code = code
        self.param_id = param_id

    @property
    def param(self) -> str:
        """The offending parameter's name (``param_<id>`` for an id the table does not list)."""
        return BY_ID[self.param_id].name if self.param_id in BY_ID else f"param_{self.param_id}"


def merge(current: Mapping[str, int], update: Mapping[int, int], streaming: bool) -> dict[str, int]:
    """The whole configuration after ``update`` (wire id → value), or ConfigRejected for the first
    failure in SPEC §4.3 order: unknown id, range/odd/step, non-live change while streaming, then
    the cross-parameter rules of §5.2 on the merged result."""
    new = dict(current)
    for pid, value in update.items():
        p = BY_ID.get(pid)
        if p is None:
            raise ConfigRejected(ErrorCode.UNKNOWN_PARAM, pid, f"unknown parameter id {pid}")
        why = p.check(value)
        if why:
            raise ConfigRejected(ErrorCode.OUT_OF_RANGE, pid, why)
        if streaming and not p.live and value != new[p.name]:
            raise ConfigRejected(ErrorCode.BAD_STATE, pid, f"{p.name} cannot change while streaming; stop first")
        new[p.name] = value
    cross_check(new, update)
    return new


def cross_check(c: Mapping[str, int], update: Mapping[int, int]) -> None:
    """SPEC §5.2 on the merged configuration ``c``; blames the first listed parameter ``update`` touched."""
    def reject(message: str, *blame: str) -> ConfigRejected:
        pid = next((BY_NAME[n].pid for n in blame if BY_NAME[n].pid in update), BY_NAME[blame[0]].pid)
        return ConfigRejected(ErrorCode.OUT_OF_RANGE, pid, message)

    if c["block_size"] > min(c["width"], c["height"]):
        raise reject(f"block_size={c['block_size']} larger than the image {c['width']}x{c['height']}",
                     "block_size", "width", "height")
    if c["pre_filter_size"] > min(c["width"], c["height"]):
        raise reject(f"pre_filter_size={c['pre_filter_size']} larger than the image {c['width']}x{c['height']}",
                     "pre_filter_size", "width", "height")
    span = c["min_disparity"] + c["num_disparities"] + c["block_size"] // 2
    if span >= c["width"] or -c["min_disparity"] >= c["width"]:
        raise reject(f"disparity range {c['min_disparity']}..{c['min_disparity'] + c['num_disparities']}"
                     f" does not fit in width {c['width']}", "num_disparities", "min_disparity", "width")
    if c["trigger_mode"] == TriggerMode.FREE_RUN and c["exposure_us"] > 1_000_000 // c["fps"]:
        raise reject(f"exposure_us={c['exposure_us']} longer than the frame period at fps={c['fps']}",
                     "exposure_us", "fps")
