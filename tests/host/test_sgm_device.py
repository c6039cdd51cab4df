"""A simulated camera configured for semi-global matching streams SGM disparity, over every
transport; switching back to block matching takes effect on the next frame."""
from __future__ import annotations

import numpy as np

from stereocam.stereo import Matcher, SGMMatcher, SGMParams
from stereocam.protocol.params import Algorithm
from stereocam.stereo.engines import params_from_config


def _one_frame(cam):
    cam.trigger()
    return cam.get_frame(timeout=30)


def test_device_streams_sgm_disparity(cam):
    cfg = cam.configure(algorithm=Algorithm.SEMI_GLOBAL, sgm_paths=4, sgm_p1=12, sgm_p2=100, census_width=7,
                        census_height=5, speckle_window_size=40, speckle_range=32)
    params = params_from_config(cfg)
    assert isinstance(params, SGMParams) and params.paths == 4 and params.census_width == 7
    cam.set_trigger_mode("software")
    cam.start()
    f = _one_frame(cam)
    want = SGMMatcher(f.left.shape, params).match(f.left, f.right)
    assert np.array_equal(f.disparity, want)  # the device ran exactly this SGM
    valid = f.disparity != f.disparity_format.invalid
    assert f.disparity_format.invalid == -16 and valid.mean() > 0.5

    cfg = cam.configure(algorithm=Algorithm.BLOCK_MATCHING)  # live: the next capture uses block matching again
    g = _one_frame(cam)
    bm = Matcher(g.left.shape, params_from_config(cfg)).match(g.left, g.right)
    assert np.array_equal(g.disparity, bm)
    assert not np.array_equal(g.disparity, SGMMatcher(g.left.shape, params).match(g.left, g.right))


def test_device_table_defaults_are_the_library_defaults():
    from stereocam.protocol.params import BY_NAME, defaults

    d = SGMParams()
    sgm = params_from_config({**defaults(), "algorithm": Algorithm.SEMI_GLOBAL})
    assert (sgm.p1, sgm.p2, sgm.p2_adapt, sgm.paths, sgm.census_width, sgm.census_height) == (
        d.p1, d.p2, d.p2_adapt, d.paths, d.census_width, d.census_height)
    # every census window the table allows, the dense census's 62 bits too (the default sparse
    # one's 32 leave room)
    assert BY_NAME["sgm_p2"].hi + SGMParams(census_sparse=False).max_cost == 255
    assert d.max_cost == 32
    for w in range(3, 10, 2):
        for h in range(1, 8, 2):
            params_from_config({**defaults(), "algorithm": Algorithm.SEMI_GLOBAL, "census_width": w,
                                "census_height": h, "sgm_p2": BY_NAME["sgm_p2"].hi})
