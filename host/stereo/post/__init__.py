"""On-board post-processing of a disparity map (SPEC §5.3), one module per stage, each a numba
kernel bit-exact with the plain numpy reference in tests/support/post_reference.py:

    lr_check.py (left-right check; the right view from the mirrored pair) -> holes.py (nearest,
    background) -> spatial.py (domain transform) -> temporal.py (with persistence) -> median.py ->
    decimation.py; chain.py runs them in that order, params.py reads them from a configuration,
    presets.py names combinations.

    from stereocam.stereo.post import postprocess, PostParams, POST_PRESETS
    out = postprocess(disp, left, PostParams(hole_fill=2), right, SGMParams(num_disparities=64))
"""
from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "STAGES": "chain", "PostChain": "chain", "postprocess": "chain", "POST_CONFIG": "params",
    "PostParams": "params", "post_params_from_config": "params", "POST_PRESETS": "presets",
    "preset_config": "presets",
}
__all__ = list(_EXPORTS)


def __getattr__(name: str) -> Any:
    """Names import on first use: the presets and parameters need no numba, the stages do."""
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f".{module}", __name__), name)
