"""``stereocam conformance``: the simulator conforms over every transport (in-process, a pty, TCP,
simulated USB; or the camera given with ``--device``), and devices broken at the byte level
(tests/support/broken_devices.py) fail, the report naming the check."""
from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import struct
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

import stereocam
from stereocam.device_sim.process import ServedSimulator
from stereocam.protocol import messages as m
from stereocam.protocol.framing import Packet
from stereocam.protocol.params import BY_ID
from stereocam.tools import cli
from stereocam.tools.conformance.checks.config import UNUSED_PARAM_ID
from tests.tools.conformance.test_device import KNOWN_SIMULATOR_GAPS
from tests.support.broken_devices import (RewritingProxy, blinding_decoder, clamp_into_range, commit_what_is_staged,
                                          counting_stop_discards, dead_trigger_output, first_duplicate_wins,
                                          forget_resend, generations_restart, link_dropping_decoder,
                                          rescan_timed_decoder, small_sgm_limit,
                                          stale_slot_report, typed_busy_nack, unchanged, without_features)

# Through the rewriting proxy: the checks the breakage is about, and enough around them to show
# that everything else still passes (the proxy re-encodes requests, so the decoder-level link
# checks are judged directly against the devices, not through it).
PROXY_CHECKS = r"^(identity|config|link\.resend|trigger\.software|session)"
BUILT_HERE = pytest.mark.sim_only("judges simulators and broken devices this module builds")


def _run_cli(argv: list[str]) -> tuple[int, str]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        rc = cli.main(["conformance", *argv])
    return rc, out.getvalue()


def _failures(report: dict) -> set[str]:
    return {c["name"] for c in report["checks"] if c["outcome"] in ("FAIL", "ERROR")}


@pytest.fixture(scope="module")
def tcp_sim():
    with ServedSimulator("tcp:127.0.0.1:0", seed=31) as sim:
        yield sim


@BUILT_HERE
def test_the_command_in_its_own_process(tcp_sim, tmp_path):
    """The installed command as a separate process against the served simulator: text lines,
    the summary, the exit status and a JUnit file a CI system reads."""
    junit = tmp_path / "conformance.xml"
    proc = subprocess.run([sys.executable, "-m", "stereocam.tools.cli", "conformance", tcp_sim.url,
                           "-k", r"^(identity|config\.cross|link\.large|session)", "--junit", str(junit)],
                          capture_output=True, text=True, timeout=120)
    lines = proc.stdout.splitlines()
    checks = [ln.split()[:2] for ln in lines[:-1]]
    assert {outcome for outcome, _ in checks} <= {"PASS", "FAIL", "SKIP"}
    failed = {name for outcome, name in checks if outcome == "FAIL"}
    assert failed <= set(KNOWN_SIMULATOR_GAPS), proc.stdout
    assert proc.returncode == (1 if failed else 0), proc.stderr
    assert lines[-1].startswith("DOES NOT CONFORM" if failed else "CONFORMS") and f"{len(checks)} checks" in lines[-1]
    root = ET.parse(junit).getroot()
    cases = root.findall("./testsuite/testcase")
    assert sorted(c.get("name") for c in cases) == sorted(name for _, name in checks)
    assert int(root.get("tests")) == len(checks) and int(root.get("failures")) == len(failed)


@BUILT_HERE
def test_the_suite_never_loads_the_simulator(tcp_sim):
    """It judges through the protocol alone: a fresh process running it imports no device_sim."""
    code = ("import sys; from stereocam.tools.conformance import run_suite; "
            f"r = run_suite({tcp_sim.url!r}, only=lambda n: n.startswith(('identity', 'time'))); "
            "print(r.passed, sorted(n for n in sys.modules if 'device_sim' in n))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60).stdout
    assert out.split() == ["True", "[]"]


@BUILT_HERE
def test_the_proxy_alone_breaks_nothing_and_only_table_parameters_cross_the_wire(tcp_sim):
    """Control for the broken devices below: a pass-through proxy passes the same checks. It also
    records every SET_CONFIG: the suite sets only parameters of the protocol table (plus the one
    id it sends on purpose to be refused), so nothing simulator-only crosses the wire."""
    sent: set[int] = set()

    def record(p: Packet) -> Packet:
        if p.msg_type == m.MsgType.SET_CONFIG:
            with contextlib.suppress(struct.error):  # the malformed lists the suite sends on purpose
                sent.update(m.SetConfig.unpack(p.payload).values)
        return unchanged(p)

    with RewritingProxy(tcp_sim.url, record) as proxy:
        rc, out = _run_cli([proxy.url, "--json", "-k", PROXY_CHECKS])
    report = json.loads(out)
    assert rc == 0 and not _failures(report), out
    assert {"link.resend_replayed", "link.resend_trigger", "config.limits.fps"} <= {c["name"] for c in report["checks"]}
    assert sent - set(BY_ID) == {UNUSED_PARAM_ID}


@BUILT_HERE
def test_fails_against_a_device_that_applies_a_retried_command_twice(tcp_sim, tmp_path):
    junit = tmp_path / "retry.xml"
    with RewritingProxy(tcp_sim.url, forget_resend) as proxy:
        rc, out = _run_cli([proxy.url, "--json", "-k", PROXY_CHECKS, "--junit", str(junit)])
    report = json.loads(out)
    assert rc == 1 and not report["passed"]
    assert _failures(report) == {"link.resend_replayed", "link.resend_trigger"}, out
    details = {c["name"]: c["detail"] for c in report["checks"]}
    assert "TIME_SYNC resent" in details["link.resend_replayed"] and "executed twice" in details["link.resend_replayed"]
    assert "resent TRIGGER executed twice" in details["link.resend_trigger"]
    failed_cases = [c.get("name") for c in ET.parse(junit).getroot().iter("testcase") if c.find("failure") is not None]
    assert sorted(failed_cases) == ["link.resend_replayed", "link.resend_trigger"]


@BUILT_HERE
def test_fails_against_a_device_whose_slot_report_disagrees_with_what_runs(tcp_sim):
    with RewritingProxy(tcp_sim.url, unchanged, to_host=stale_slot_report) as proxy:
        rc, out = _run_cli([proxy.url, "--json", "-k", "update"])
    report = json.loads(out)
    assert rc == 1 and _failures(report) == {"update.status"}, out
    detail = next(c["detail"] for c in report["checks"] if c["name"] == "update.status")
    assert "-stale" in detail and "INFO" in detail


def test_fails_against_a_device_that_accepts_out_of_range_values(tcp_sim):
    with RewritingProxy(tcp_sim.url, clamp_into_range) as proxy:
        rc, out = _run_cli([proxy.url, "-k", PROXY_CHECKS])
    lines = out.splitlines()
    failed = {ln.split()[1] for ln in lines[:-1] if ln.startswith("FAIL")}
    assert rc == 1 and lines[-1].startswith("DOES NOT CONFORM")
    limits = {ln.split()[1] for ln in lines if ln.split()[1:2] and ln.split()[1].startswith("config.limits.")}
    assert limits and limits <= failed  # every parameter's out-of-range probe now "accepted"
    assert "config.all_or_nothing" in failed  # fps=0 beside a valid gain went through
    assert all(name.startswith("config.") for name in failed), failed  # nothing else is affected
    fps_line = next(ln for ln in lines if ln.split()[1:2] == ["config.limits.fps"])
    assert "fps=0 (below the range) accepted, expected NACK OUT_OF_RANGE" in fps_line


@BUILT_HERE
def test_fails_against_a_device_whose_trigger_output_never_pulses(tcp_sim):
    with RewritingProxy(tcp_sim.url, dead_trigger_output) as proxy:
        rc, out = _run_cli([proxy.url, "--json", "-k", r"^trigger\."])
    report = json.loads(out)
    assert rc == 1 and _failures(report) == {"trigger.output"}, out
    detail = next(c["detail"] for c in report["checks"] if c["name"] == "trigger.output")
    assert "0 captures" in detail and "trigger master" in detail


@BUILT_HERE
def test_what_a_device_does_not_advertise_is_skipped_with_the_reason(tcp_sim):
    """A unit without external trigger and calibration storage (its INFO says so): those checks
    are skipped, naming the capability, and the unit still conforms."""
    no = m.Capability.EXTERNAL_TRIGGER | m.Capability.CALIBRATION
    to_device, to_host = without_features(no)
    with RewritingProxy(tcp_sim.url, to_device, to_host=to_host) as proxy:
        rc, out = _run_cli([proxy.url, "-k", r"^(identity|config\.limits\.trigger_mode|trigger\.external|calib|session)"])
    lines = out.splitlines()
    skipped = {ln.split()[1]: ln for ln in lines if ln.startswith("SKIP")}
    calib = {"calib.read", "calib.write_restore", "calib.refusals", "calib.generation_after_restore",
             "calib.partial_commit"}
    assert set(skipped) == {"trigger.external", *calib}, out
    assert "EXTERNAL_TRIGGER not advertised" in skipped["trigger.external"]
    assert all("CALIBRATION not advertised" in skipped[n] for n in calib)
    assert rc == 0 and lines[-1].startswith("CONFORMS") and "6 skipped" in lines[-1], out
    # the details say what happened: trigger_mode=2 refused for want of the capability (issue 21 item 2)
    mode = next(ln for ln in lines if ln.split()[1:2] == ["config.limits.trigger_mode"])
    assert "2 refused (capability not advertised)" in mode and "0 accepted" in mode, mode
    unknown = next(ln for ln in lines if ln.split()[1:2] == ["identity.unknown_type"])
    assert "CALIBRATION UNKNOWN_TYPE" in unknown, unknown


@BUILT_HERE
def test_a_unit_that_hides_a_capability_but_accepts_its_value_fails(tcp_sim):
    """INFO without EXTERNAL_TRIGGER while trigger_mode=2 is still accepted: SPEC §5.1 demands the
    refusal (issue 21 item 1), so config.limits.trigger_mode fails; CALIB_READ still known without
    CALIBRATION fails identity.unknown_type (SPEC §4.0 capability groups)."""
    _, to_host = without_features(m.Capability.EXTERNAL_TRIGGER | m.Capability.CALIBRATION)
    with RewritingProxy(tcp_sim.url, unchanged, to_host=to_host) as proxy:
        rc, out = _run_cli([proxy.url, "--json", "-k", r"^(identity|config\.limits\.trigger_mode$)"])
    report = json.loads(out)
    assert rc == 1 and _failures(report) == {"config.limits.trigger_mode", "identity.unknown_type"}, out


@BUILT_HERE
def test_fails_against_a_device_that_does_not_enforce_its_stage_limit(tcp_sim):
    """INFO stage limits are promises (SPEC §4.1, §5.2 rule 8): SGM at 1280x960 accepted by a unit
    whose INFO says SGM stops at 640x480 fails config.limits.algorithm."""
    with RewritingProxy(tcp_sim.url, unchanged, to_host=small_sgm_limit) as proxy:
        rc, out = _run_cli([proxy.url, "--json", "-k", r"^(identity\.info|config\.limits\.(algorithm|width))$"])
    report = json.loads(out)
    assert rc == 1 and _failures(report) == {"config.limits.algorithm"}, out
    detail = next(c["detail"] for c in report["checks"] if c["name"] == "config.limits.algorithm")
    assert "accepted, expected NACK OUT_OF_RANGE" in detail, detail


# Each check added for issue 21's gaps, failing against a device broken in exactly that way.
GAP_BREAKAGES = {
    "config.duplicate_id": dict(rewrite=first_duplicate_wins),
    "stream.stop_not_dropped": dict(to_host_factory=counting_stop_discards),
    "link.message_timeout": dict(decoder=rescan_timed_decoder),
    "link.stray_header_keeps_host": dict(decoder=blinding_decoder),
    "link.first_frame_deadline": dict(speak_for_silent_host=True),
    "link.second_client": dict(to_host=typed_busy_nack),
    "calib.generation_after_restore": dict(to_host_factory=generations_restart),
    "calib.partial_commit": dict(rewrite=commit_what_is_staged),
}
GAP_DETAILS = {
    "config.duplicate_id": "the last value must be used",
    "stream.stop_not_dropped": "discarded captures are not drops",
    "link.message_timeout": "from its own arrival",
    "link.stray_header_keeps_host": "stray header",
    "link.first_frame_deadline": "never spoke is still open",
    "link.second_client": "request_type 1",
    "calib.generation_after_restore": "can name two commits",
    "calib.partial_commit": "expected BAD_PAYLOAD",
}


@BUILT_HERE
@pytest.mark.parametrize("name", sorted(GAP_BREAKAGES))
def test_each_new_check_fails_against_a_device_broken_that_way(tcp_sim, name):
    how = dict(GAP_BREAKAGES[name])
    factory = how.pop("to_host_factory", None)
    rewrite = how.pop("rewrite", unchanged)
    if factory is not None:
        how["to_host"] = factory()
    with RewritingProxy(tcp_sim.url, rewrite, **how) as proxy:
        rc, out = _run_cli([proxy.url, "--json", "-k", f"^{name.replace('.', chr(92) + '.')}$"])
    report = json.loads(out)
    assert rc == 1 and _failures(report) == {name}, out
    detail = next(c["detail"] for c in report["checks"] if c["name"] == name)
    assert GAP_DETAILS[name] in detail, detail


@BUILT_HERE
def test_a_link_dropped_behind_stray_headers_fails_the_message_timeout_rule(tcp_sim):
    """A unit whose stuck receive path ends in a dropped link (or whose watchdog trips while the
    check waits, on a loaded machine) fails link.message_timeout with the rule, not a bare
    disconnect."""
    with RewritingProxy(tcp_sim.url, unchanged, decoder=link_dropping_decoder) as proxy:
        rc, out = _run_cli([proxy.url, "--json", "-k", r"^link\.message_timeout$"])
    report = json.loads(out)
    assert rc == 1 and _failures(report) == {"link.message_timeout"}, out
    detail = next(c["detail"] for c in report["checks"] if c["name"] == "link.message_timeout")
    assert "the link dropped" in detail and GAP_DETAILS["link.message_timeout"] in detail, detail


@BUILT_HERE
def test_the_new_checks_pass_against_the_simulator_over_tcp(tcp_sim):
    rc, out = _run_cli([tcp_sim.url, "--json", "-k", "^(" + "|".join(n.replace(".", r"\.") for n in GAP_BREAKAGES)
                        + ")$"])
    report = json.loads(out)
    assert rc == 0 and {c["name"] for c in report["checks"] if c["outcome"] == "PASS"} >= set(GAP_BREAKAGES), out


@BUILT_HERE
def test_leaves_a_unit_with_a_user_record_as_found(tcp_sim):
    """The calibration checks write and restore records; a unit that held a user record holds
    the same body again afterwards, in force."""
    with stereocam.open(tcp_sim.url) as cam:
        factory = cam.read_calibration("factory")
        k = factory.calibration.K_right.copy()
        k[1, 1] -= 0.5
        mine = cam.write_calibration(dataclasses.replace(factory.calibration, K_right=k), "user")
    try:
        rc, out = _run_cli([tcp_sim.url, "--json", "-k", r"^(calib|session)"])
        report = json.loads(out)
        assert rc == 0 and {c["name"] for c in report["checks"] if c["outcome"] == "PASS"} >= {
            "calib.read", "calib.write_restore", "calib.refusals", "session.restored"}, out
        with stereocam.open(tcp_sim.url) as cam:
            user, active = cam.read_calibration("user"), cam.read_calibration("active")
            assert user.body == mine.body
            assert active.calibration_id == mine.calibration_id == cam.info().calibration_id
    finally:
        with stereocam.open(tcp_sim.url) as cam:
            cam.restore_factory_calibration()


@pytest.mark.parametrize("timeout, words", [
    ("nan", "not a finite number"), ("inf", "not in the range"), ("1e20", "not in the range"),
    ("0", "not in the range"), ("-1", "not in the range"), ("61", "0<x<=60")])
def test_a_timeout_that_cannot_be_waited_is_a_usage_error(monkeypatch, capsys, timeout: str, words: str):
    """Refused before the camera is opened (nan is no device failure, inf no overflow deep in a transport)."""
    def opened(*args: object, **kwargs: object) -> None:
        raise AssertionError("the camera was opened")

    monkeypatch.setattr("stereocam.tools.conformance.cli.run_suite", opened)
    rc, out = _run_cli(["socket://127.0.0.1:9", "--timeout", timeout])
    err = capsys.readouterr().err
    assert rc == 2 and words in err and "'--timeout'" in err and "Traceback" not in err and not out


@pytest.mark.parametrize("junit, words", [("", "must name a file, got an empty value"),
                                          ("{tmp}/nodir/r.xml", "nodir is not a folder"),
                                          ("/proc/r.xml", "cannot write into directory '/proc'")])
def test_a_junit_path_that_cannot_be_written_is_refused_before_any_check(monkeypatch, capsys, tmp_path, junit, words):
    """Audit: --junit was checked only after the whole suite had run; --junit '' said "Is a directory: '.'"."""
    def ran(*args: object, **kwargs: object) -> None:
        raise AssertionError("the suite ran")

    monkeypatch.setattr("stereocam.tools.conformance.cli.run_suite", ran)
    rc, out = _run_cli(["socket://127.0.0.1:9", "--junit", junit.replace("{tmp}", str(tmp_path))])
    err = capsys.readouterr().err
    assert rc == 2 and words in err and "'--junit'" in err and "Traceback" not in err and not out
