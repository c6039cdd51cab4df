"""``stereocam demo``: values it cannot run with are usage errors (exit 2, one line, no traceback),
refused before a simulator is built; a run shorter than a frame still streams one."""
from __future__ import annotations

import pytest

from stereocam.tools import cli
from stereocam.tools.demo import cli as demo


@pytest.mark.parametrize("argv, words", [
    (["--seconds", "nan"], "'nan' is not a finite number"),
    (["--seconds", "inf"], "not in the range"), (["--seconds", "1e20"], "not in the range"),
    (["--seconds", "-inf"], "not in the range"), (["--heads", "2", "--seconds", "nan"], "not a finite number"),
    (["--heads", "2", "--seconds", "inf"], "not in the range"),
    (["--seed", "-1"], "0<=x<=4294967295"), (["--seed", "99999999999"], "0<=x<=4294967295"),
    (["--heads", "3", "--seed", "4294967294"], "seeds 4294967294..4294967296")])
def test_values_a_demo_cannot_run_with_are_refused_before_any_simulator(monkeypatch, capsys, tmp_path, argv, words):
    def built(*args: object, **kwargs: object) -> None:
        raise AssertionError("a simulator was built")

    monkeypatch.setattr(demo, "SimulatedCamera", built)
    monkeypatch.setattr(demo.demo_group, "run", built)
    assert cli.main(["demo", "--out", str(tmp_path / "out"), *argv]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_a_run_shorter_than_a_frame_streams_one(capsys, tmp_path):
    assert cli.main(["demo", "--seconds", "1e-9", "--fps", "30", "--out", str(tmp_path), "--json"]) == 0
    assert '"frames": 1' in capsys.readouterr().out
