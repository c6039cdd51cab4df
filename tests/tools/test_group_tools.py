"""``stereocam demo --heads N`` and ``stereocam bench sync`` (short runs: the figures are the bench's job)."""
from __future__ import annotations

import subprocess
import sys

import pytest

from stereocam.tools import cli
from stereocam.tools.bench import sync as bench_sync
from stereocam.tools.conformance.budget import budget


def test_demo_with_three_heads_prints_sets_and_saves_each_head(tmp_path, capsys):
    assert cli.main(["demo", "--heads", "3", "--seconds", "2", "--fps", "8", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    line = [ln for ln in out.splitlines() if ln.startswith("summary:")][0]
    fields = dict(kv.split("=") for kv in line.split()[1:] if "=" in kv)
    assert int(fields["complete"]) >= 1 and int(fields["sets"]) == int(fields["complete"]) + int(fields["incomplete"])
    assert out.count("clock map error estimate") == 3
    assert {p.name.split("_t")[0] for p in tmp_path.glob("*_left.png")} == {"demo_HEAD1", "demo_HEAD2", "demo_HEAD3"}


@pytest.mark.slow
def test_bench_sync_reports_skew_and_clock_errors_per_transport(capsys):
    # the deadline stretched by the suite's time factor: under load a head's frames come late, not never
    out = bench_sync.command.main(["--seconds", "1", "--transports", "inprocess,tcp", "--deadline", str(budget(1.0))],
                                  standalone_mode=False)
    assert set(out) == {"inprocess", "tcp"}
    for fig in out.values():
        assert fig["sets"] > 0 and 0 <= fig["skew_p50_us"] <= fig["skew_p99_us"] <= fig["skew_max_us"]
        assert sum(k.endswith("_err_sigma_us") for k in fig) == 3
    assert "clock map error vs truth" in capsys.readouterr().out


@pytest.mark.slow
def test_bench_sync_through_the_command_tree_takes_its_seconds(capsys):
    """`stereocam bench sync --seconds N` captures N s per transport (not the mode's 120 s default)."""
    assert cli.main(["bench", "sync", "--seconds", "2", "--transports", "inprocess"]) == 0
    out = capsys.readouterr().out
    assert "2 s per transport" in out and "inprocess" in out


@pytest.mark.parametrize("args, named", [
    (["--trigger-line", "../etc"], "--trigger-line"),
    (["--vendor-key", "/nonexistent/key.pem"], "No such file"),
    (["--vendor-key", __file__], "not a PEM private key"),
])
def test_a_served_unit_refuses_bad_arguments_with_a_message_and_exit_2(args, named):
    r = subprocess.run([sys.executable, "-m", "stereocam.device_sim", "--serve", "tcp:127.0.0.1:0", *args],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and named in r.stderr and "Traceback" not in r.stderr
