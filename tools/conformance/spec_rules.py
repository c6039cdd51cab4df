"""Rules from protocol/SPEC.md that the codec does not hold, restated for the judge.

§5.2 cross-parameter constraints (with their blame order) and the values a limit probe sends.
Restated here on purpose: the judge must not take the rules from the firmware it judges.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from stereocam.protocol import messages as m
from stereocam.protocol.params import BY_NAME, Param, TriggerMode

INT32_MIN, INT32_MAX = -(1 << 31), (1 << 31) - 1
RAW_OUTPUT = getattr(m.Capability, "RAW_OUTPUT", 0x20)  # SPEC §4.1 bit 5: rectify=0 gives raw frames


@dataclass(frozen=True)
class CrossRule:
    name: str
    names: tuple[str, ...]  # parameters the rule reads
    blame: tuple[str, ...]  # NACK.param_id: the first of these the request contains, else the first
    violated: Callable[[dict[str, int]], bool]


CROSS_RULES: tuple[CrossRule, ...] = (
    CrossRule("block_size_vs_image", ("block_size", "width", "height"), ("block_size", "width", "height"),
              lambda c: c["block_size"] > min(c["width"], c["height"])),
    CrossRule("pre_filter_size_vs_image", ("pre_filter_size", "width", "height"),
              ("pre_filter_size", "width", "height"),
              lambda c: c["pre_filter_size"] > min(c["width"], c["height"])),
    CrossRule("disparity_range_vs_width", ("min_disparity", "num_disparities", "block_size", "width"),
              ("num_disparities", "min_disparity", "width"),
              lambda c: (c["min_disparity"] < 0 and -c["min_disparity"] >= c["width"])
              or c["min_disparity"] + c["num_disparities"] + c["block_size"] // 2 >= c["width"]),
    CrossRule("exposure_vs_frame_period", ("trigger_mode", "exposure_us", "fps"), ("exposure_us", "fps"),
              lambda c: c["trigger_mode"] == TriggerMode.FREE_RUN and c["exposure_us"] > 1_000_000 // c["fps"]),
)


def cross_violation(config: dict[str, int], touched: set[str]) -> tuple[CrossRule, str] | None:
    """The first §5.2 rule ``config`` breaks and the parameter the NACK must name, or None.
    Rules reading a parameter the device does not have are not applied."""
    for rule in CROSS_RULES:
        if all(n in config for n in rule.names) and rule.violated(config):
            return rule, next((n for n in rule.blame if n in touched), rule.blame[0])
    return None


def effective_hi(p: Param, max_width: int, max_height: int) -> int:
    """The largest value the device must accept: INFO.max_width / max_height cap the size table."""
    cap = {"width": max_width, "height": max_height}.get(p.name)
    if cap is None:
        return p.hi
    return min(p.hi, cap - (cap - p.lo) % p.step)


def optional_values(capabilities: int) -> set[tuple[str, int]]:
    """Values within the table that a device may refuse OUT_OF_RANGE because it does not advertise
    the capability behind them (SPEC §5.1: rectify=0 needs RAW_OUTPUT)."""
    return set() if capabilities & RAW_OUTPUT else {("rectify", 0)}


def limit_probes(p: Param, hi: int) -> tuple[list[int], list[tuple[int, str]]]:
    """Values at the limits (to be accepted) and beyond them (to be refused OUT_OF_RANGE, with why)."""
    accept = [p.lo, hi] if hi != p.lo else [p.lo]
    refuse = [(p.lo - 1, "below the range"), (hi + 1, "above the range"),
              (INT32_MIN, "int32 minimum"), (INT32_MAX, "int32 maximum")]
    if p.odd:
        refuse.append((p.lo + 1, "even, must be odd"))
    if p.step > 1:
        refuse.append((p.lo + p.step // 2, f"not a multiple of {p.step}"))
    return accept, refuse


def roomy_base(max_width: int, max_height: int, advertised: set[str]) -> dict[str, int]:
    """A configuration in which every parameter's own limits satisfy every cross rule: the largest
    image, the smallest matcher windows and disparity range, triggered (no frame-period rule)."""
    base = {"width": effective_hi(BY_NAME["width"], max_width, max_height),
            "height": effective_hi(BY_NAME["height"], max_width, max_height),
            "num_disparities": BY_NAME["num_disparities"].lo, "block_size": BY_NAME["block_size"].lo,
            "pre_filter_size": BY_NAME["pre_filter_size"].lo, "min_disparity": 0,
            "trigger_mode": int(TriggerMode.SOFTWARE)}
    return {k: v for k, v in base.items() if k in advertised}
