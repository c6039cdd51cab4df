"""The device runs the post-processing chain (SPEC §5.3) after its engine: what it sends is the host's
``postprocess`` of the engine's disparity, bit for bit; the temporal filter forgets its past on a
configuration change and on a trigger gap."""
from __future__ import annotations

import numpy as np

from stereocam.camera import Camera
from stereocam.device_sim import SimulatedCamera
from stereocam.device_sim.links.inprocess import InProcessTransport
from stereocam.device_sim.pipeline.stereo import TRIGGER_GAP_PERIODS, StereoStage
from stereocam.protocol.params import defaults
from stereocam.stereo import match
from stereocam.stereo.engines import params_from_config
from stereocam.stereo.post import POST_PRESETS, PostParams, post_params_from_config, postprocess
from tests.support.device import SMALL


def test_the_device_sends_the_chain_of_the_engine_output() -> None:
    cfg = {**SMALL, **POST_PRESETS["high_density"], "lr_check": 1, "decimation": 2}
    sim = SimulatedCamera(seed=7)
    with Camera(InProcessTransport(sim, owns=True)) as cam:
        cam.configure(**cfg)
        cam.start()
        frame = cam.get_frame(timeout=60)
        cam.stop()
    full = {**defaults(), **cfg}
    engine = params_from_config(full)
    raw = match(frame.left, frame.right, engine)
    want = postprocess(raw, frame.left, post_params_from_config(full), frame.right, engine)
    assert np.array_equal(frame.disparity, want)
    assert (raw == engine.invalid_value).any() and not (frame.disparity == engine.invalid_value).any()


def _stage_cfg(**post: int) -> dict[str, int]:
    return {**defaults(), **SMALL, "width": 64, "height": 48, "num_disparities": 16, "block_size": 5,
            "fps": 10, "texture_threshold": 0, **post}


def test_temporal_state_resets_on_a_configuration_change_and_a_trigger_gap() -> None:
    """A pixel the engine leaves invalid keeps the previous frame's value (persistence) while frames
    come on time with the same configuration, and not after a gap or a change."""
    rng = np.random.default_rng(0)
    textured = rng.integers(0, 256, (48, 80), dtype=np.uint8)
    left, right = textured[:, 4:68].copy(), textured[:, :64].copy()  # a 4 px shift
    flat = np.full((48, 64), 90, np.uint8)  # no texture: no disparity anywhere
    cfg = _stage_cfg(temporal_alpha=128, temporal_persistence=3)
    period = 1 / cfg["fps"]
    stage = StereoStage()
    first = stage.disparity(cfg, left, right, at=0.0)
    assert (first == 4 * 16).any()
    held = stage.disparity(cfg, flat, flat, at=period)
    assert np.array_equal(held, first)  # on time: every pixel held
    stage.disparity(cfg, left, right, at=2 * period)
    after_gap = stage.disparity(cfg, flat, flat, at=(3 + TRIGGER_GAP_PERIODS) * period)
    assert (after_gap == -16).all()
    stage.disparity(cfg, left, right, at=10.0)
    changed = stage.disparity({**cfg, "temporal_delta": 48}, flat, flat, at=10.0 + period)
    assert (changed == -16).all()


def test_post_params_default_off_and_read_from_a_configuration() -> None:
    assert not post_params_from_config(defaults()).active
    assert post_params_from_config({"hole_fill": 2}) == PostParams(hole_fill=2)  # a pre-1.3 config: the rest off


def test_the_confidence_plane_is_sent_alone_or_with_the_disparity() -> None:
    from stereocam.protocol.params import Output
    from tests.support import post_reference as ref

    cfg = {**SMALL, "algorithm": 1, "hole_fill": 2, "outputs": int(Output.LEFT | Output.RIGHT | Output.DISPARITY
                                                                     | Output.CONFIDENCE)}
    sim = SimulatedCamera(seed=7)
    with Camera(InProcessTransport(sim, owns=True)) as cam:
        cam.configure(**cfg)
        cam.start()
        frame = cam.get_frame(timeout=60)
        cam.configure(outputs=int(Output.LEFT | Output.CONFIDENCE))
        alone = next(f for f in iter(lambda: cam.get_frame(timeout=60), None) if f.disparity is None)
        cam.stop()
    engine = params_from_config({**defaults(), **cfg})
    raw = match(frame.left, frame.right, engine)
    assert frame.confidence is not None and frame.confidence.dtype == np.uint8
    assert np.array_equal(frame.confidence, ref.confidence(raw, frame.disparity, engine.invalid_value))
    assert alone.confidence is not None and alone.right is None and (alone.confidence == 16).any()
