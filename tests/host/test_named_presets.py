"""Named presets (``cam.load_preset('high_density')``): they set the values they name, leave the rest,
and a device running one sends a full-density disparity."""
from __future__ import annotations

import numpy as np
import pytest

import stereocam
from stereocam.stereo.post import POST_PRESETS
from tests.support.device import SMALL


def test_a_named_preset_sets_its_values_and_keeps_the_rest() -> None:
    with stereocam.open("sim://?seed=3", timeout=2.0) as cam:
        cam.configure(**SMALL, exposure_us=2345)
        cfg = cam.load_preset("high_density")
        assert {k: cfg[k] for k in POST_PRESETS["high_density"]} == dict(POST_PRESETS["high_density"])
        assert cfg["exposure_us"] == 2345 and cfg["width"] == SMALL["width"]
        cam.start()
        frame = cam.get_frame(timeout=60)
        cam.stop()
        assert not (frame.disparity == frame.disparity_format.invalid).any()
        cfg = cam.load_preset("off")
        assert cfg["hole_fill"] == 0 and cfg["algorithm"] == 1  # off: the chain only


def test_an_unknown_name_is_a_config_error_naming_the_known_ones() -> None:
    with stereocam.open("sim://?seed=3", timeout=2.0) as cam:
        with pytest.raises(stereocam.ConfigError, match="high_density"):
            cam.load_preset("high_densty")


def test_presets_are_valid_configuration_values() -> None:
    from stereocam.protocol.params import BY_NAME
    for name, values in POST_PRESETS.items():
        assert all(BY_NAME[k].check(v) is None for k, v in values.items()), name
        assert np.all([k in BY_NAME for k in values])


@pytest.mark.parametrize("name", ["high-density", "", "HIGH_DENSITY"])
def test_a_mistyped_name_lists_the_known_ones(name: str) -> None:
    from stereocam.presets import preset_values
    from stereocam.stereo.post.presets import preset_config
    with pytest.raises(stereocam.ConfigError, match="known: high_density"):
        preset_values(name)
    with pytest.raises(stereocam.ConfigError, match="a preset name is a string"):
        preset_config(["high_density"])  # type: ignore[arg-type]
