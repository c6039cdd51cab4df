"""Cross-parameter rules (SPEC §5.2): each rule broken from either side, the NACK blaming the right
parameter, the configuration unchanged; and values on the legal side accepted."""
from __future__ import annotations

from typing import Iterator

from stereocam.protocol import messages as m
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.params import Algorithm, TriggerMode

from .. import spec_rules
from ..context import Context
from ..registry import CheckFn, family
from ..results import expect
from ..wire import describe_nack

Case = tuple[dict[str, int], dict[str, int]]  # (setup applied first, the probe SET_CONFIG)

# From the working configuration (320x240, num_disparities 32, block_size 11, pre_filter_size 9,
# min_disparity 0, fps 15, exposure_us 4000, free-run). Whether each probe must be refused, and
# which parameter the NACK names, is computed from the rules, not written here.
CASES: dict[str, list[Case]] = {
    "block_size_vs_image": [({}, {"block_size": 241}), ({"block_size": 101}, {"height": 96}),
                            ({"block_size": 101}, {"width": 96, "height": 96}), ({}, {"block_size": 239})],
    "pre_filter_size_vs_image": [({}, {"pre_filter_size": 241}), ({"pre_filter_size": 101}, {"height": 96}),
                                 ({}, {"pre_filter_size": 239})],
    "disparity_range_vs_width": [({}, {"min_disparity": 300}), ({}, {"min_disparity": -320}),
                                 ({}, {"num_disparities": 256, "min_disparity": 64}),
                                 ({"num_disparities": 128}, {"width": 128}), ({}, {"min_disparity": -100})],
    "sgm_disparity_range_vs_width": [
        ({"algorithm": Algorithm.SEMI_GLOBAL}, {"min_disparity": 256, "num_disparities": 80}),
        ({"algorithm": Algorithm.SEMI_GLOBAL}, {"min_disparity": 200, "num_disparities": 32}),
        ({"algorithm": Algorithm.SEMI_GLOBAL, "min_disparity": 250, "num_disparities": 64},
         {"algorithm": Algorithm.BLOCK_MATCHING}),
        ({"algorithm": Algorithm.SEMI_GLOBAL}, {"min_disparity": -256, "num_disparities": 256})],
    "exposure_vs_frame_period": [({}, {"exposure_us": 70_000}), ({"exposure_us": 50_000}, {"fps": 30}),
                                 ({"trigger_mode": TriggerMode.SOFTWARE}, {"exposure_us": 500_000}),
                                 ({"trigger_mode": TriggerMode.SOFTWARE, "exposure_us": 500_000},
                                  {"trigger_mode": TriggerMode.FREE_RUN})],
    "trigger_output_needs_external": [({}, {"trigger_output": 1}),
                                      ({"trigger_mode": TriggerMode.SOFTWARE}, {"trigger_output": 1}),
                                      ({"trigger_mode": TriggerMode.EXTERNAL}, {"trigger_output": 1}),
                                      ({"trigger_mode": TriggerMode.EXTERNAL, "trigger_output": 1},
                                       {"trigger_mode": TriggerMode.FREE_RUN})],
    "exposure_vs_output_period": [({"trigger_mode": TriggerMode.EXTERNAL, "exposure_us": 100_000},
                                   {"trigger_output": 1}),
                                  ({"trigger_mode": TriggerMode.EXTERNAL, "trigger_output": 1},
                                   {"exposure_us": 70_000}),
                                  ({"trigger_mode": TriggerMode.EXTERNAL, "trigger_output": 1, "exposure_us": 50_000},
                                   {"fps": 30}),
                                  ({"trigger_mode": TriggerMode.EXTERNAL, "trigger_output": 1},
                                   {"exposure_us": 60_000})],
}


@family("config.cross", "R-5.2-1")
def cross_rules(ctx: Context) -> Iterator[tuple[str, CheckFn]]:
    for rule in spec_rules.CROSS_RULES:
        yield rule, _rule_check(rule)


def _rule_check(rule: str) -> CheckFn:
    def run(ctx: Context) -> str:
        ctx.require_params(*spec_rules.CROSS_RULES[rule])
        for capability in spec_rules.capabilities_read(spec_rules.CROSS_RULES[rule]):
            ctx.require(capability)
        refused = accepted = 0
        for setup, probe in CASES[rule]:
            ctx.reset()
            if _case(ctx, setup, probe):
                refused += 1
            else:
                accepted += 1
        return f"{refused} violations refused naming the right parameter, {accepted} legal neighbours accepted"
    return run


def _case(ctx: Context, setup: dict[str, int], probe: dict[str, int]) -> bool:
    """Apply ``setup``, send ``probe``; True if it was (rightly) refused."""
    cfg = ctx.apply(**{k: int(v) for k, v in setup.items()})
    refusal = spec_rules.cross_refusal({**cfg, **probe}, set(probe), spec_rules.stage_limits(ctx.info))
    r = ctx.set(**probe)
    shown = ", ".join(f"{k}={int(v)}" for k, v in probe.items()) + (f" after {setup}" if setup else "")
    if refusal is None:
        expect(isinstance(r, m.ConfigApplied), f"{shown}: legal, but {describe_nack(r) if isinstance(r, m.Nack) else r!r}")
        return False
    expect(isinstance(r, m.Nack), f"{shown} breaks SPEC §5.2 ({refusal}) but was accepted")
    assert isinstance(r, m.Nack)
    expect(r.code == ErrorCode.OUT_OF_RANGE and r.param_id == refusal.param_id,
           f"{shown} ({refusal}): {describe_nack(r)}, expected OUT_OF_RANGE naming {refusal.param} "
           f"({refusal.param_id})")
    expect(ctx.config() == cfg, f"{shown} refused but the configuration changed")
    return True
