"""The CI-sized soak (issue 9): each fuzz and the faulty-link stream, short; the long run is `make soak`."""
from __future__ import annotations

import pytest

from stereocam.tools import cli
from stereocam.tools.soak import cli as soak
from stereocam.tools.soak.group import lying_head_group
from stereocam.tools.soak.parts import fuzz_decoder, fuzz_device


def test_decoder_fuzz_short():
    rep = fuzz_decoder(3000, seed=5)
    assert rep.inputs == 3000 and rep.crashes == rep.hangs == 0 and rep.figures["invariant violations"] == 0


def test_device_fuzz_short():
    rep = fuzz_device("sim://?seed=6", 150, seed=6)
    assert rep.inputs == 150 and rep.crashes == rep.hangs == 0 and rep.figures["answered"] == 150


def test_soak_command_short(capsys):
    rc = cli.main(["soak", "sim://?seed=7", "--decoder-inputs", "500", "--device-inputs", "30", "--seconds", "4",
                   "--flip", "1e-4", "--recording-files", "5", "--group-seconds", "2"])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "soak: clean" in out and "corrupted: 0" in out and "counters add up: yes" in out
    assert "delivery goal: met (at least 50%)" in out


def test_soak_fails_a_stream_short_of_its_delivery_goal():
    """A report whose delivery is below the goal for its flip rate fails the soak, said so."""
    rep = soak.Report("stream, flip 1e-05/byte")
    rep.figures.update({"frames sent": 100, "delivered": 94, "corrupted": 0})
    assert soak._failed(rep, 1e-5) and rep.figures["delivery goal"].startswith("NOT MET")
    rep.figures["delivered"] = 95
    assert not soak._failed(rep, 1e-5)


def test_hostile_recording_stage_short():
    """Issue 22: the bombs and fuzzed recordings through export, repair, replay and rematch: no
    crash, no hang, nothing changed outside the outputs, memory bounded."""
    from stereocam.tools.soak.recordings import fuzz_recordings

    rep = fuzz_recordings(8, seed=3, hang_s=60)
    f = rep.figures
    assert rep.inputs == 8 * 4 and rep.crashes == 0 and rep.hangs == 0, f
    assert f["files changed outside the output"] == 0 and f["operations refused (damaged, exit 1/2)"] >= 3 * 3
    assert f["peak memory MiB"] < 2048


def test_the_soak_fails_a_file_changed_outside_the_output():
    rep = soak.Report("hostile recordings", inputs=4)
    rep.figures.update({"files changed outside the output": 1, "peak memory MiB": 100})
    assert soak._failed(rep)
    rep.figures["files changed outside the output"] = 0
    assert not soak._failed(soak._memory_goal(rep, 2048)) and soak._failed(soak._memory_goal(rep, 50))
def test_lying_head_group_stage_short():
    """Issue 22: one head's trigger ids jump by 10^6..2^32; the group neither crashes nor hangs, names
    the liar, and its memory stays bounded."""
    rep = lying_head_group(3.0, seed=3)
    f = rep.figures
    assert rep.crashes == rep.hangs == 0 and f["sets"] > 10 and f["liar named"].startswith("LIAR3-1 ")
    assert "memory goal" not in f and not soak._failed(rep)


@pytest.mark.parametrize("argv, words", [
    (["--latency", "nan"], "'nan' is not a finite number"), (["--latency", "inf"], "not in the range"),
    (["--latency", "1e300"], "not in the range"), (["--seconds", "nan"], "'nan' is not a finite number"),
    (["--seconds", "inf"], "'inf' is not a finite number"), (["--flip", "1e-4", "--flip", "nan"], "not a finite number"),
    (["--drop", "nan"], "not a finite number"), (["--group-seconds", "inf"], "not a finite number"),
    (["--seed", "-1"], "not in the range")])
def test_values_a_soak_cannot_run_with_are_usage_errors_before_any_stage(monkeypatch, capsys, argv, words):
    def ran(*args: object, **kwargs: object) -> None:
        raise AssertionError("a stage ran")

    monkeypatch.setattr(soak, "fuzz_decoder", ran)
    assert cli.main(["soak", *argv]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err
