"""What the high_density preset is for: on a scene with exact ground truth, every pixel a disparity
and bad-2.0 (all pixels, invalid counted as bad) at least 25 % below the best cv2.StereoSGBM mode."""
from __future__ import annotations

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from stereocam.protocol.params import defaults  # noqa: E402
from stereocam.stereo import match  # noqa: E402
from stereocam.stereo.engines import params_from_config  # noqa: E402
from stereocam.stereo.post import POST_PRESETS, post_params_from_config, postprocess  # noqa: E402
from stereocam.tools.bench.matching import bad_rate, synthetic_scene  # noqa: E402

ND = 64


def test_high_density_beats_every_sgbm_mode_at_full_density() -> None:
    left, right, gt = synthetic_scene(240, 320, seed=4)
    cfg = {**defaults(), "num_disparities": ND, **POST_PRESETS["high_density"]}
    engine = params_from_config(cfg)
    raw = match(left, right, engine)
    ours = postprocess(raw, left, post_params_from_config(cfg), right, engine)
    density = np.count_nonzero(ours != engine.invalid_value) / ours.size
    sgbm = []
    for mode in (cv2.STEREO_SGBM_MODE_SGBM, cv2.STEREO_SGBM_MODE_HH, cv2.STEREO_SGBM_MODE_SGBM_3WAY,
                 cv2.STEREO_SGBM_MODE_HH4):
        m = cv2.StereoSGBM_create(0, ND, 5, P1=200, P2=800, disp12MaxDiff=1, uniquenessRatio=10,
                                  speckleWindowSize=100, speckleRange=2, mode=mode)
        sgbm.append(bad_rate(m.compute(left, right), gt, -16))
    bad = bad_rate(ours, gt, engine.invalid_value)
    assert density >= 0.99
    assert bad <= 0.75 * min(sgbm), (bad, sgbm)
    assert bad < bad_rate(raw, gt, engine.invalid_value)  # the chain, not the engine alone
