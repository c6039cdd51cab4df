"""On-board post-processing of a disparity map (SPEC §5.6), one module per stage, each a numba
kernel bit-exact with the plain numpy reference in tests/support/post_reference.py:

    lr_check.py (left-right check; the right view from the mirrored pair) -> holes.py (nearest,
    background) -> spatial.py (domain transform) -> temporal.py (with persistence) -> median.py ->
    decimation.py; chain.py runs them in that order, params.py reads them from a configuration,
    presets.py names combinations.

    from stereocam.stereo.post import postprocess, PostParams, POST_PRESETS
    out = postprocess(disp, left, PostParams(hole_fill=2), right, SGMParams(num_disparities=64))
"""
from __future__ import annotations

from .chain import STAGES, PostChain, postprocess
from .params import POST_CONFIG, PostParams, post_params_from_config
from .presets import POST_PRESETS, preset_config

__all__ = ["STAGES", "PostChain", "postprocess", "POST_CONFIG", "PostParams", "post_params_from_config",
           "POST_PRESETS", "preset_config"]
