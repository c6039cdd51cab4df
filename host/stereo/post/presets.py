"""Named combinations of device parameters (``cam.load_preset('high_density')``, the CLI, the viewer):
the matching engine's settings and the post-processing chain's, as configuration values."""
from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from stereocam.protocol.errors import ConfigError
from stereocam.protocol.params import Algorithm

from .params import POST_CONFIG, PostParams

_OFF = {f.key: getattr(PostParams(), f.field) for f in POST_CONFIG}
_SHARP = {"sgm_p1": 25, "sgm_p2": 100}
"""The default P1 with a lighter P2 than the default 190: sharper edges for the left-right check, the
fill and the speckle filter the presets run. Measured on Motorcycle and every scene class at seeds 3 and
5, then 7 and 11 (after the out-of-image cost became 3/8 of the census bits): mean bad-2.0 of
high_density 7.27 / 7.44 % against 8.87 / 8.99 at the former 6 / 55 and 8.03 / 8.23 at 25 / 190 (P1
22-26 with P2 80-110 all within 0.3 of it); high_accuracy 83.5 / 83.0 % dense at 3.23 / 3.34 % bad-2.0
of its pixels, against 80.4 / 79.9 at 3.79 / 3.98 (6 / 55)."""

POST_PRESETS: Mapping[str, Mapping[str, int]] = MappingProxyType({
    # every pixel a disparity: the engine's left-right check (as good as the mirrored pair's here, at
    # no cost), its holes and the occlusions filled from the background, then smoothed
    "high_density": MappingProxyType({**_OFF, **_SHARP, "algorithm": Algorithm.SEMI_GLOBAL, "uniqueness_ratio": 0,
                                      "disp12_max_diff": 1, "speckle_window_size": 100, "speckle_range": 32,
                                      "hole_fill": 2, "spatial_alpha": 128, "spatial_delta": 32,
                                      "spatial_iterations": 1, "median_size": 3}),
    # fewer, surer pixels: strict left-right check, speckles removed, no filling
    "high_accuracy": MappingProxyType({**_OFF, **_SHARP, "algorithm": Algorithm.SEMI_GLOBAL, "uniqueness_ratio": 10,
                                       "speckle_window_size": 200, "speckle_range": 16, "lr_check": 1,
                                       "median_size": 3}),
    # the chain off (the engines' raw output)
    "off": MappingProxyType(dict(_OFF)),
})
"""Preset name -> the configuration values it sets (others keep their values)."""


def preset_config(name: str) -> dict[str, int]:
    """The configuration values preset ``name`` sets (ConfigError naming the known ones)."""
    if not isinstance(name, str):
        raise ConfigError(f"a preset name is a string, got {type(name).__name__}; known: {', '.join(POST_PRESETS)}")
    try:
        return {k: int(v) for k, v in POST_PRESETS[name].items()}
    except KeyError:
        raise ConfigError(f"unknown preset {name!r}; known: {', '.join(POST_PRESETS)}") from None
