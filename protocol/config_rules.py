"""Which configurations a device accepts (SPEC §4.3 steps 2–3, §5.2): one rule set for both sides.

The device's config store applies an update with ``merge``; the host checks a would-be
configuration with it before sending (``Camera.check_config``). The device stays the authority:
the host check only spares a round trip and names the parameter earlier.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass

from .errors import ConfigError, ErrorCode
from .messages import Capability, Stage
from .params import BY_ID, BY_NAME, Algorithm, TriggerMode


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


CAPABILITY_VALUES: dict[tuple[str, int], int] = {
    ("trigger_mode", TriggerMode.EXTERNAL): Capability.EXTERNAL_TRIGGER,
    ("rectify", 0): Capability.RAW_OUTPUT,
    ("trigger_output", 1): Capability.TRIGGER_OUTPUT,
    ("algorithm", Algorithm.SEMI_GLOBAL): Capability.SGM,
}
"""Values within the table that only a device advertising the capability accepts (SPEC §5.1
*Capability-bound values*); a device without it NACKs them OUT_OF_RANGE. Judge with the negotiated
capabilities (``Info.effective_capabilities``): a 1.2 device has SGM without the bit."""

STAGE_OF_ALGORITHM: dict[int, int] = {Algorithm.BLOCK_MATCHING: Stage.BLOCK_MATCHING,
                                      Algorithm.SEMI_GLOBAL: Stage.SEMI_GLOBAL}
"""The INFO stage (SPEC §4.1 stage limits) each ``algorithm`` value runs."""

StageLimits = Mapping[int, tuple[int, int]]
"""Stage id -> (max_width, max_height), the INFO stage limits a device advertises (SPEC §4.1)."""


def merge(current: Mapping[str, int], update: Mapping[int, int] | Iterable[tuple[int, int]], streaming: bool,
          capabilities: int | None = None, stage_limits: StageLimits | None = None) -> dict[str, int]:
    """The whole configuration after ``update`` (wire id → value, or the (id, value) entries of a
    SET_CONFIG in payload order, duplicates included), or ConfigRejected for the first failure in
    SPEC §4.3 order: every entry's id, range/odd/step (and a value whose capability ``capabilities``
    lacks; None: not checked), non-live change while streaming (against ``current``), then the
    cross-parameter rules of §5.2 on the merged result, the last (rule 8) against ``stage_limits``."""
    pairs = tuple(update.items()) if isinstance(update, Mapping) else tuple(update)
    new = dict(current)
    for pid, value in pairs:
        p = BY_ID.get(pid)
        if p is None:
            raise ConfigRejected(ErrorCode.UNKNOWN_PARAM, pid, f"unknown parameter id {pid}")
        why = p.check(value)
        needs = CAPABILITY_VALUES.get((p.name, value))
        if not why and capabilities is not None and needs is not None and not capabilities & needs:
            why = f"{p.name}={value} needs INFO capability {Capability.name_of(needs)}, which this device lacks"
        if why:
            raise ConfigRejected(ErrorCode.OUT_OF_RANGE, pid, why)
        if streaming and not p.live and value != current[p.name]:
            raise ConfigRejected(ErrorCode.BAD_STATE, pid, f"{p.name} cannot change while streaming; stop first")
        new[p.name] = value
    cross_check(new, dict(pairs))
    if stage_limits:
        check_stage_limits(new, dict(pairs), stage_limits)
    return new


def check_stage_limits(c: Mapping[str, int], update: Mapping[int, int], stage_limits: StageLimits) -> None:
    """SPEC §5.2 rule 8: the selected matching stage's INFO limit bounds width and height; the NACK
    names the first of width, height, algorithm that ``update`` touched, else width."""
    stage = STAGE_OF_ALGORITHM.get(_algorithm(c))
    if stage is None or stage not in stage_limits:
        return
    max_w, max_h = stage_limits[stage]
    if c["width"] <= max_w and c["height"] <= max_h:
        return
    touched = {BY_ID[pid].name for pid in update if pid in BY_ID}
    blamed = next((n for n in ("width", "height", "algorithm") if n in touched), "width")
    raise ConfigRejected(ErrorCode.OUT_OF_RANGE, BY_NAME[blamed].pid,
                         f"{c['width']}x{c['height']} exceeds what the selected matcher (INFO stage {stage}) "
                         f"supports: {max_w}x{max_h}")


@dataclass(frozen=True)
class CrossRule:
    """One SPEC §5.2 constraint between parameters."""

    name: str
    names: tuple[str, ...]  # parameters the rule reads
    blame: tuple[str, ...]  # NACK.param_id: the first of these the update touched, else the first
    violated: Callable[[Mapping[str, int]], bool]
    why: Callable[[Mapping[str, int]], str]


def _algorithm(c: Mapping[str, int]) -> int:
    """The matcher the configuration selects (a device without ``algorithm`` does block matching)."""
    return c.get("algorithm", Algorithm.BLOCK_MATCHING)


def _largest_disparity(c: Mapping[str, int]) -> int:
    return c["min_disparity"] + c["num_disparities"] - 1


def _bm_no_valid_column(c: Mapping[str, int]) -> bool:
    """The block matcher's geometry (SPEC §5.2 rule 3): the columns it can compute, shifted by the
    largest disparity on the left and by the most negative one on the right, must leave at least
    one column whose whole window (block_size/2 either side) lies in the image."""
    d_max, r = _largest_disparity(c), c["block_size"] // 2
    return max(d_max, 0) + 2 * r >= c["width"] or max(-d_max, 0) + c["num_disparities"] - 1 >= c["width"]


def _sgm_no_valid_column(c: Mapping[str, int]) -> bool:
    """The semi-global matcher's geometry (SPEC §5.2 rule 5): it matches the columns where every
    disparity of the range has its right pixel in the image, [max(d_max, 0), width + min(min_disparity, 0))."""
    return min(c["width"], c["width"] + c["min_disparity"]) - max(_largest_disparity(c), 0) < 1


def _range_why(c: Mapping[str, int], window: str) -> str:
    return (f"disparity range {c['min_disparity']}..{_largest_disparity(c)}{window} leaves no column of width "
            f"{c['width']} where a disparity can be valid")


# What each matching engine needs of the frame (stereocam/stereo: block matching with OpenCV
# StereoBM semantics, SGM): a rule for one engine applies only while ``algorithm`` selects it, and
# an engine with new needs adds its rows here, so host check and device keep one table.
CROSS_RULES: tuple[CrossRule, ...] = (
    CrossRule("block_size_vs_image", ("block_size", "width", "height"), ("block_size", "width", "height", "algorithm"),
              lambda c: _algorithm(c) == Algorithm.BLOCK_MATCHING and c["block_size"] >= min(c["width"], c["height"]),
              lambda c: f"block_size={c['block_size']} larger than the image {c['width']}x{c['height']} allows"),
    CrossRule("pre_filter_size_vs_image", ("pre_filter_size", "width", "height"),
              ("pre_filter_size", "width", "height"),
              lambda c: c["pre_filter_size"] > min(c["width"], c["height"]),
              lambda c: f"pre_filter_size={c['pre_filter_size']} larger than the image {c['width']}x{c['height']}"),
    CrossRule("disparity_range_vs_width", ("min_disparity", "num_disparities", "block_size", "width"),
              ("num_disparities", "min_disparity", "width", "block_size", "algorithm"),
              lambda c: _algorithm(c) == Algorithm.BLOCK_MATCHING and _bm_no_valid_column(c),
              lambda c: _range_why(c, f" with block_size={c['block_size']}")),
    CrossRule("exposure_vs_frame_period", ("trigger_mode", "exposure_us", "fps"), ("exposure_us", "fps"),
              lambda c: c["trigger_mode"] == TriggerMode.FREE_RUN and c["exposure_us"] > 1_000_000 // c["fps"],
              lambda c: f"exposure_us={c['exposure_us']} longer than the frame period at fps={c['fps']}"),
    CrossRule("sgm_disparity_range_vs_width", ("algorithm", "min_disparity", "num_disparities", "width"),
              ("num_disparities", "min_disparity", "width", "algorithm"),
              lambda c: _algorithm(c) == Algorithm.SEMI_GLOBAL and _sgm_no_valid_column(c),
              lambda c: _range_why(c, "")),
    CrossRule("trigger_output_needs_external", ("trigger_output", "trigger_mode"), ("trigger_output", "trigger_mode"),
              lambda c: c["trigger_output"] == 1 and c["trigger_mode"] != TriggerMode.EXTERNAL,
              lambda c: "trigger_output=1 needs trigger_mode=external: the master captures on its own pulses "
                        "like every head on the line"),
    CrossRule("exposure_vs_output_period", ("trigger_output", "exposure_us", "fps"),
              ("exposure_us", "fps", "trigger_output"),
              lambda c: c["trigger_output"] == 1 and c["exposure_us"] > 1_000_000 // c["fps"],
              lambda c: f"exposure_us={c['exposure_us']} longer than the trigger period at fps={c['fps']}"),
)
"""SPEC §5.2, in the order a device checks them."""


def cross_violation(config: Mapping[str, int], touched: set[str]) -> tuple[CrossRule, str] | None:
    """The first rule ``config`` breaks and the parameter its NACK names, or None. Rules reading a
    parameter the configuration does not have are not applied."""
    for rule in CROSS_RULES:
        if all(n in config for n in rule.names) and rule.violated(config):
            return rule, next((n for n in rule.blame if n in touched), rule.blame[0])
    return None


def cross_check(c: Mapping[str, int], update: Mapping[int, int]) -> None:
    """SPEC §5.2 on the merged configuration ``c``; blames the first listed parameter ``update`` touched."""
    clash = cross_violation(c, {BY_ID[pid].name for pid in update if pid in BY_ID})
    if clash is not None:
        rule, blamed = clash
        raise ConfigRejected(ErrorCode.OUT_OF_RANGE, BY_NAME[blamed].pid, rule.why(c))
