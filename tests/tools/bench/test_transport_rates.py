"""``stereocam bench transport --rates``: the pipeline rate targets, measured over sim and TCP."""
from __future__ import annotations

import importlib.util

import pytest

from stereocam.tools.bench import transport


@pytest.mark.slow
def test_rates_prints_each_target_over_sim_and_tcp(capsys):
    out = transport.command.main(["--rates", "--seconds", "0.5"], standalone_mode=False)
    printed = capsys.readouterr().out
    for case in transport.RATE_CASES[:2]:
        for kind in transport.RATE_KINDS:
            assert out[f"{kind}_{case.label}_fps"] > 0
            assert f"{kind:<9} {case.fps:>5}" in printed.split(case.label, 1)[1]
    assert "load average" in printed
    profiles = [line for line in printed.splitlines() if "device stages, ms per frame" in line]
    ran = transport.RATE_CASES if importlib.util.find_spec("stereocam.stereo.post") else transport.RATE_CASES[:2]
    assert len(profiles) == len(ran)  # one per case run, for sim (the device in this process)
    assert all("render" in line and "match" in line and "CPU" in line for line in profiles)
    if importlib.util.find_spec("stereocam.stereo.post") is None:
        assert "+ high_density (skipped: stereocam.stereo.post" in printed
