"""The post-processing checks (tools/conformance/checks/post.py) pass on the simulator and fail, naming
the stage, against devices broken at the byte level (tests/support/broken_devices.py)."""
from __future__ import annotations

import json

import pytest

from stereocam.device_sim.process import ServedSimulator
from stereocam.protocol import messages as m
from stereocam.tools.conformance.checks.post import POST_PARAMS, STAGES
from tests.tools.conformance.test_cli import BUILT_HERE, _failures, _run_cli
from tests.support.broken_devices import RewritingProxy, ignore_params, unchanged, without_capabilities

STAGE_CHECKS = {f"post.stage.{name}" for name in STAGES}


@pytest.fixture(scope="module")
def tcp_sim():
    with ServedSimulator("tcp:127.0.0.1:0", seed=32) as sim:
        yield sim


@BUILT_HERE
def test_the_simulator_passes_every_post_check(tcp_sim):
    rc, out = _run_cli([tcp_sim.url, "--json", "-k", r"^post\."])
    report = json.loads(out)
    passed = {c["name"] for c in report["checks"] if c["outcome"] == "PASS" and c["name"].startswith("post.")}
    assert rc == 0 and passed == {"post.capability", *STAGE_CHECKS}, out


@BUILT_HERE
def test_every_stage_check_fails_against_a_device_that_never_runs_its_stage(tcp_sim):
    with RewritingProxy(tcp_sim.url, ignore_params(*POST_PARAMS)) as proxy:
        rc, out = _run_cli([proxy.url, "--json", "-k", r"^post\."])
    report = json.loads(out)
    assert rc == 1 and _failures(report) == STAGE_CHECKS, out
    detail = {c["name"]: c["detail"] for c in report["checks"]}
    assert "hole_fill=2" in detail["post.stage.hole_fill_background"]
    assert "differs from the host's chain" in detail["post.stage.median"]


@BUILT_HERE
def test_the_capability_check_fails_when_the_parameters_come_without_the_bit(tcp_sim):
    with RewritingProxy(tcp_sim.url, unchanged, to_host=without_capabilities(m.Capability.POST_PROCESSING)) as proxy:
        rc, out = _run_cli([proxy.url, "--json", "-k", r"^post\."])
    report = json.loads(out)
    assert rc == 1 and _failures(report) == {"post.capability"}, out
    skipped = {c["name"] for c in report["checks"] if c["outcome"] == "SKIP"}
    assert skipped == STAGE_CHECKS
