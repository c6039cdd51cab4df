"""What the judge expects of a configuration: SPEC §5.2 through the protocol's own rule set
(protocol/config_rules.py, never the firmware's), the values a limit probe sends, the roomy
configuration in which every parameter's limits are legal."""
from __future__ import annotations

from stereocam.protocol import config_rules
from stereocam.protocol import messages as m
from stereocam.protocol.config_rules import ConfigRejected, StageLimits, check_stage_limits, cross_check
from stereocam.protocol.params import BY_NAME, INT32_MAX, INT32_MIN, Param, TriggerMode, defaults



CROSS_RULES: dict[str, tuple[str, ...]] = {r.name: r.names for r in config_rules.CROSS_RULES}
"""SPEC §5.2, in order: each rule and the parameters it reads."""


def cross_refusal(config: dict[str, int], touched: set[str], stage_limits: StageLimits | None = None
                  ) -> ConfigRejected | None:
    """The refusal SPEC §5.2 demands for ``config`` reached by changing ``touched`` (the NACK's
    parameter and why), or None; rule 8 against ``stage_limits`` (INFO's). Parameters the device
    lacks take the table's defaults."""
    merged, update = {**defaults(), **config}, {BY_NAME[n].pid: config[n] for n in touched}
    try:
        cross_check(merged, update)
        if stage_limits:
            check_stage_limits(merged, update, stage_limits)
    except ConfigRejected as refusal:
        return refusal
    return None


def stage_limits(info: m.Info) -> dict[int, tuple[int, int]]:
    """INFO's stage limits as §5.2 rule 8 reads them (a stage without an entry: the device's maxima)."""
    return {stage: info.stage_limit(stage) for stage in (m.Stage.BLOCK_MATCHING, m.Stage.SEMI_GLOBAL)}


def effective_hi(p: Param, max_width: int, max_height: int) -> int:
    """The largest value the device must accept: INFO.max_width / max_height cap the size table."""
    cap = {"width": max_width, "height": max_height}.get(p.name)
    if cap is None:
        return p.hi
    return min(p.hi, cap - (cap - p.lo) % p.step)


def optional_values(capabilities: int) -> set[tuple[str, int]]:
    """Values within the table that a device may refuse OUT_OF_RANGE because it does not advertise
    the capability behind them (SPEC §5.1: rectify=0 needs RAW_OUTPUT, trigger_output=1 TRIGGER_OUTPUT)."""
    return {value for value, needs in config_rules.CAPABILITY_VALUES.items() if not capabilities & needs}


def capabilities_read(names: tuple[str, ...]) -> list[int]:
    """The capabilities behind values of these parameters (a rule over them needs them to be probed)."""
    return sorted({needs for (name, _), needs in config_rules.CAPABILITY_VALUES.items() if name in names})


def limit_probes(p: Param, hi: int) -> tuple[list[int], list[tuple[int, str]]]:
    """Values at the limits (to be accepted) and beyond them (to be refused OUT_OF_RANGE, with why)."""
    accept = [p.lo, hi] if hi != p.lo else [p.lo]
    refuse = [(p.lo - 1, "below the range"), (hi + 1, "above the range"),
              (INT32_MIN, "int32 minimum"), (INT32_MAX, "int32 maximum")]
    if p.odd:
        refuse.append((p.lo + 1, "even, must be odd"))
    if p.step > 1:
        refuse.append((p.lo + p.step // 2, f"not a multiple of {p.step}"))
    if p.one_of:
        accept = sorted(set(accept) | {v for v in p.one_of if v <= hi})
        refuse.append((next(v for v in range(p.lo, hi + 1) if v not in p.one_of),
                       f"not one of {', '.join(map(str, p.one_of))}"))
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
