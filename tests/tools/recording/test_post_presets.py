"""The named presets from the command line: ``stereocam record --preset`` records what the device's
chain sends, ``stereocam rematch --preset`` runs the same chain on the host."""
from __future__ import annotations

import numpy as np

from stereocam.recording.reader import Recording
from stereocam.stereo import match
from stereocam.stereo.engines import params_from_config
from stereocam.stereo.post import post_params_from_config, postprocess
from stereocam.tools import cli


def test_record_and_rematch_with_presets(tmp_path):
    src = tmp_path / "in" / "run.mcap"
    src.parent.mkdir()
    assert cli.main(["record", "sim://?seed=9", "--out", str(src), "--frames", "3", "--preset", "high_density",
                     "--set", "width=320", "--set", "height=240", "--set", "num_disparities=32", "--quiet"]) == 0
    with Recording(src) as rec:
        assert rec.config["hole_fill"] == 2 and rec.config["width"] == 320
        assert all(not (c.disparity == c.to_frame().disparity_format.invalid).any() for c in rec.captures())
    assert cli.main(["rematch", str(src), "--out", str(tmp_path / "out"), "--preset", "high_accuracy",
                     "--workers", "1"]) == 0
    with Recording(src) as a, Recording(tmp_path / "out" / "run.mcap") as b:
        cfg = b.config
        assert cfg["hole_fill"] == 0 and cfg["lr_check"] == 1
        engine, post = params_from_config(cfg), post_params_from_config(cfg)
        for ca, cb in zip(a.captures(), b.captures(), strict=True):
            want = postprocess(match(ca.left, ca.right, engine), ca.left, post, ca.right, engine)
            assert np.array_equal(cb.disparity, want)
            assert (cb.disparity == engine.invalid_value).any()  # the left-right check's holes stay


def test_an_unknown_preset_is_a_usage_error(tmp_path, capsys):
    assert cli.main(["record", "sim://?seed=9", "--out", str(tmp_path / "x.mcap"), "--frames", "1",
                     "--preset", "dense"]) == 2
    assert "high_density" in capsys.readouterr().err
