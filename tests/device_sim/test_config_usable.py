"""Every configuration the protocol's rules accept is one the matcher can run (issue 9 item 6):
the SPEC §5.2 rules say exactly what the block matcher needs of the frame geometry, no less (an
accepted configuration that fails every capture) and no more (a usable one refused)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from stereocam.stereo.engines import matcher_for
from stereocam.protocol.config_rules import ConfigRejected, merge
from stereocam.protocol.params import BY_NAME, defaults

GEOMETRY = ("algorithm", "width", "height", "num_disparities", "block_size", "min_disparity")


def legal(name: str) -> st.SearchStrategy[int]:
    """Values the parameter's own range/odd/step rules allow."""
    p = BY_NAME[name]
    if p.odd:
        return st.integers((p.lo + 1) // 2, (p.hi - 1) // 2).map(lambda k: 2 * k + 1)
    step = p.step
    return st.integers(0, (p.hi - p.lo) // step).map(lambda k: p.lo + k * step)


def accepted(cfg: dict[str, int]) -> bool:
    try:
        merge(defaults(), {BY_NAME[n].pid: cfg[n] for n in GEOMETRY}, streaming=False)
        return True
    except ConfigRejected:
        return False


def runnable(cfg: dict[str, int]) -> bool:
    """The firmware's matcher (the one ``algorithm`` selects) can be built for this format (its own
    parameter validation)."""
    try:
        matcher_for(cfg, (cfg["height"], cfg["width"]))
        return True
    except ValueError:
        return False


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.fixed_dictionaries({n: legal(n) for n in GEOMETRY}))
@example({"algorithm": 0, "width": 640, "height": 480, "num_disparities": 256, "block_size": 255, "min_disparity": 200})
@example({"algorithm": 0, "width": 64, "height": 48, "num_disparities": 16, "block_size": 47, "min_disparity": 0})
@example({"algorithm": 1, "width": 64, "height": 48, "num_disparities": 16, "block_size": 255, "min_disparity": 48})
def test_the_rules_accept_exactly_what_the_matcher_can_run(geometry) -> None:
    cfg = {**defaults(), **geometry}
    assert accepted(cfg) == runnable(cfg), f"rules and matcher disagree on {geometry}"


@settings(max_examples=25, deadline=None)
@given(st.fixed_dictionaries({n: legal(n) for n in GEOMETRY}), st.integers(0, 2**32 - 1))
def test_every_accepted_geometry_matches_a_pair(geometry, seed) -> None:
    cfg = {**defaults(), **geometry}
    if not accepted(cfg):
        return
    rng = np.random.default_rng(seed)
    left = rng.integers(0, 256, (cfg["height"], cfg["width"]), np.uint8)
    right = np.roll(left, -8, axis=1)
    disp = matcher_for(cfg, left.shape).match(left, right)
    assert disp.shape == left.shape and disp.dtype == np.int16


@pytest.mark.parametrize("name", ["num_disparities", "min_disparity", "width"])
def test_the_reported_case_is_refused_naming_the_parameter(name) -> None:
    bad = {"algorithm": 0, "width": 640, "height": 480, "num_disparities": 256, "block_size": 255, "min_disparity": 200}
    current = {**defaults(), **bad, name: defaults()[name] if name != "width" else 1280}
    with pytest.raises(ConfigRejected, match="disparity") as err:
        merge(current, {BY_NAME[name].pid: bad[name]}, streaming=False)
    assert err.value.param == name
