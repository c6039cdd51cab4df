"""Stereo matching engines, for the device and for host-side tools alike: StereoBM block matching,
bit-exact with cv2.StereoBM (OpenCV 4.x/5.x), and semi-global matching (census, 4, 5 or 8 paths),
bit-exact with tests/sgm_reference.py. Depends on stereocam.protocol, numpy and numba only.

    from stereocam.stereo import MatchParams, SGMParams, match, Matcher, SGMMatcher
    disp = match(left, right, MatchParams(num_disparities=64, block_size=9))  # int16, d * 16
    disp = match(left, right, SGMParams(num_disparities=128))  # semi-global matching
    m = Matcher(left.shape, params); disp = m.match(left, right)  # keeps scratch per frame
    m = SGMMatcher(left.shape, SGMParams())  # the same for SGM

The engine table (engines.py) keys the engines by the protocol's ``algorithm`` value; the device
pipeline, replay, rematch and the benches select engines there. Names below import on first use.

SGM pipeline (modules): sgm_params.py -> census.py (+ census_simd.py) -> sgm.py + sgm_simd.py (costs, paths,
selection; 5 paths: sgm_one_pass.py over sgm.py's row stages; their threads' locks and atomics:
atomics.py; the vector width: simd.LANES) -> postfilter.py (speckle filter).

Pipeline (modules): prefilter.py (XSOBEL / NORMALIZED_RESPONSE) -> sad.py + simd.py (running
SAD sums, texture, winner-take-all, uniqueness, subpixel, left-right check, valid region) ->
postfilter.py (speckle filter). numba, parallel over row stripes; ``warm_up()`` pays the JIT
(or loads numba's on-disk cache) once per process. OpenCV is the test oracle only.

Post-processing (post/, ``stereocam.stereo.post``): the device's chain after either engine — left-right
check, hole filling, spatial and temporal filters, median, decimation, the confidence plane — and the
named presets (SPEC §5.3).

Where OpenCV's own output is not well defined we do the following instead:
  * no valid column (image too narrow for range + window): ConfigError (a ValueError) (OpenCV returns all
    invalid, or its uninitialised output buffer when only the valid region is empty);
  * 32-bit costs (pre_filter_cap > 31 or block_size > 21) with disp12_max_diff >= 0: OpenCV
    writes int costs into a 16-bit buffer and its left-right check reads them back as shorts;
    we check with the true costs;
  * min_disparity > 0: OpenCV writes past each row end; only the spill into row H - r survives
    deterministically and is reproduced; spills across its thread stripes race, we drop them.
"""
from __future__ import annotations

import importlib
import os
from typing import Any

# numba's default threading layer here is OpenMP (libgomp), whose idle threads spin at every
# barrier and after every parallel region. Beside other busy processes the spinning thread
# takes the core from the one it waits for: measured on 2 cores beside a busy process, SGM
# census 51 ms wall for 2.5 ms of work, a frame 190 ms vs 50 ms passive. Read by libgomp when
# numba first starts its threads, so only in effect when that happens after this import;
# the user's own setting wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

_EXPORTS = {
    "MatchParams": "params", "geometry": "params", "SGMParams": "sgm_params", "sgm_geometry": "sgm_params",
    "Matcher": "matcher", "check_pair": "matcher", "SGMMatcher": "sgm_matcher",
    "Engine": "engines", "ENGINES": "engines", "register": "engines", "engine_for": "engines",
    "engine_named": "engines", "params_from_config": "engines", "matcher_for": "engines",
    "match": "engines", "warm_up": "engines",
}
__all__ = list(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f".{module}", __name__), name)
