"""The engine table: one row per engine keyed by the protocol's ``algorithm`` value, parameters from a
device configuration as data, and a new engine is one module plus one row (tests/stereo/sad_engine.py)."""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

import numpy as np
import pytest

from stereocam.device_sim.pipeline.stereo import StereoStage
from stereocam.protocol.errors import ConfigError
from stereocam.protocol.frame_messages import invalid_disparity
from stereocam.protocol.params import BY_NAME, Algorithm, defaults
from stereocam.recording.reader import Recording
from stereocam.stereo import MatchParams, SGMParams, engines
from stereocam.stereo.config_map import config_of
from stereocam.tools.recording import rematch_tasks
from stereocam.tools.bench.record import synthetic_recording

from . import sad_engine


@pytest.fixture
def sad() -> Iterator[engines.Engine]:
    engines.register(sad_engine.ENGINE)
    try:
        yield sad_engine.ENGINE
    finally:
        engines.unregister(sad_engine.ALGORITHM)


def _pair(h: int = 48, w: int = 64, shift: int = 5) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(4)
    right = rng.integers(0, 256, (h, w + shift), np.uint8)
    return np.ascontiguousarray(right[:, :w]), np.ascontiguousarray(right[:, shift:])


def test_every_protocol_algorithm_has_one_engine_row() -> None:
    assert sorted(engines.ENGINES) == sorted(Algorithm)
    assert BY_NAME["algorithm"].hi == max(engines.ENGINES)
    assert {engines.engine_for(a).params for a in Algorithm} == {MatchParams, SGMParams}


def test_parameters_come_from_the_configuration_by_the_rows_map() -> None:
    cfg = {**defaults(), "algorithm": Algorithm.SEMI_GLOBAL, "disp12_max_diff": 2, "sgm_paths": 4,
           "pre_filter_type": 1}
    sgm = engines.params_from_config(cfg)
    assert isinstance(sgm, SGMParams) and (sgm.lr_max_diff, sgm.paths) == (2, 4)
    bm = engines.params_from_config({**cfg, "algorithm": Algorithm.BLOCK_MATCHING})
    assert isinstance(bm, MatchParams) and bm.pre_filter_type == "normalized" and bm.disp12_max_diff == 2
    for algorithm in Algorithm:  # the map back gives the configuration values it read
        engine = engines.engine_for(algorithm)
        assert config_of(engine.params_from_config(cfg), engine.config) == {f.key: cfg[f.key] for f in engine.config}
    no_algorithm = {k: v for k, v in defaults().items() if k != "algorithm"}  # recorded before 1.2
    assert isinstance(engines.params_from_config(no_algorithm), MatchParams)


def test_parameter_limits_are_the_protocols() -> None:
    hi = BY_NAME["num_disparities"].hi
    MatchParams(num_disparities=hi)
    with pytest.raises(ConfigError, match=f"num_disparities={hi + 16} outside"):
        MatchParams(num_disparities=hi + 16)
    with pytest.raises(ConfigError, match="lr_max_diff: disp12_max_diff=-2 outside"):
        SGMParams(lr_max_diff=-2)
    with pytest.raises(ConfigError, match="pre_filter_type must be one of"):
        MatchParams(pre_filter_type="sobel")


def test_unknown_algorithms_and_clashing_rows_are_refused(sad) -> None:
    with pytest.raises(ConfigError, match="no matching engine for algorithm 7; known: 0 .bm., 1 .sgm., 2 .sad."):
        engines.params_from_config({**defaults(), "algorithm": 7})
    with pytest.raises(ConfigError, match="clashes with 'sad'"):
        engines.register(replace(sad, algorithm=9))
    with pytest.raises(ConfigError, match="clashes with 'bm'"):
        engines.register(replace(sad, algorithm=Algorithm.BLOCK_MATCHING, name="other"))
    assert engines.names() == ["bm", "sgm", "sad"] and engines.engine_named("sad") is sad


def test_a_registered_engine_runs_the_device_match_step(sad) -> None:
    left, right = _pair()
    cfg = {**defaults(), "width": 64, "height": 48, "algorithm": sad_engine.ALGORITHM, "block_size": 7,
           "num_disparities": 16, "min_disparity": 0}
    stage = StereoStage()
    disp = stage.disparity(cfg, left, right)
    want = sad_engine.sad_disparity(left, right, sad_engine.SADParams(16, 0, 7))
    assert np.array_equal(disp, want)
    valid = disp != invalid_disparity(0)
    assert valid.mean() > 0.5 and np.mean(disp[valid] == 5 * 16) > 0.9  # it finds the shift
    bm = stage.disparity({**cfg, "algorithm": Algorithm.BLOCK_MATCHING}, left, right)
    assert not np.array_equal(bm, disp)  # the row the configuration selects, not a fixed engine
    assert np.array_equal(engines.match(left, right, sad_engine.SADParams(16, 0, 7)), want)


def test_a_registered_engine_rematches_a_recording(sad, tmp_path) -> None:
    src, part = tmp_path / "in.mcap", tmp_path / "out.mcap"
    synthetic_recording(src, 3)
    frames, _ = rematch_tasks.rematch_range(str(src), 0, 3, {"algorithm": sad_engine.ALGORITHM, "block_size": 9,
                                                              "min_disparity": -2}, str(part))
    assert frames == 3
    with Recording(src) as a, Recording(part) as b:
        assert b.config["algorithm"] == sad_engine.ALGORITHM
        for ca, cb in zip(a.captures(), b.captures(), strict=True):
            want = sad_engine.sad_disparity(ca.left, ca.right, sad_engine.SADParams(64, -2, 9))
            assert np.array_equal(cb.disparity, want) and not np.array_equal(cb.disparity, ca.disparity)
            assert cb.info.invalid_disparity == invalid_disparity(-2) and cb.info.min_disparity == -2
