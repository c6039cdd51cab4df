"""The CI-sized soak (issue 9): each fuzz and the faulty-link stream, short; the long run is `make soak`."""
from __future__ import annotations

from stereocam.tools import cli
from stereocam.tools.soak import cli as soak
from stereocam.tools.soak.parts import fuzz_decoder, fuzz_device


def test_decoder_fuzz_short():
    rep = fuzz_decoder(3000, seed=5)
    assert rep.inputs == 3000 and rep.crashes == rep.hangs == 0 and rep.figures["invariant violations"] == 0


def test_device_fuzz_short():
    rep = fuzz_device("sim://?seed=6", 150, seed=6)
    assert rep.inputs == 150 and rep.crashes == rep.hangs == 0 and rep.figures["answered"] == 150


def test_soak_command_short(capsys):
    rc = cli.main(["soak", "sim://?seed=7", "--decoder-inputs", "500", "--device-inputs", "30", "--seconds", "4",
                    "--flip", "1e-4"])
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
