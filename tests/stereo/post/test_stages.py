"""Each post-processing stage is bit-exact with the numpy reference (tests/support/post_reference.py)
on small maps with holes, edges and noise, and does what its stage is for."""
from __future__ import annotations

import numpy as np
import pytest

from stereocam.protocol.frame_messages import invalid_disparity
from stereocam.stereo.post.decimation import decimate
from stereocam.stereo.post.holes import fill_background, fill_nearest
from stereocam.stereo.post.lr_check import lr_check
from stereocam.stereo.post.median import median_filter
from stereocam.stereo.post.spatial import spatial_filter
from stereocam.stereo.post.temporal import TemporalState, temporal_filter

from tests.support import post_reference as ref

MIN_DISPARITIES = [0, -4]


def noisy_map(seed: int, min_disparity: int, h: int = 23, w: int = 37, holes: float = 0.25) -> np.ndarray:
    """A near and a far plane with subpixel noise and random holes (runs and single pixels)."""
    rng = np.random.default_rng(seed)
    inv = invalid_disparity(min_disparity)
    d = np.full((h, w), (min_disparity + 6) * 16, np.int32)
    d[h // 4:3 * h // 4, w // 3:2 * w // 3] = (min_disparity + 20) * 16
    d += rng.integers(-12, 13, d.shape)
    d[rng.random(d.shape) < holes] = inv
    d[h // 2, 2:w // 2] = inv  # a long run
    d[:3, :4] = inv  # a corner hole
    return d.astype(np.int16)


def assert_same(ours: np.ndarray, want: np.ndarray) -> None:
    assert ours.dtype == np.int16 and ours.shape == want.shape
    diff = np.argwhere(ours != want)
    assert diff.size == 0, f"{len(diff)} differ; first (y, x, ours, ref): " + str(
        [(y, x, ours[y, x], want[y, x]) for y, x in diff[:5]])


@pytest.mark.parametrize("mind", MIN_DISPARITIES)
@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("tol", [0, 1, 3])
def test_lr_check_matches_reference(seed: int, mind: int, tol: int) -> None:
    inv = invalid_disparity(mind)
    disp, right = noisy_map(seed, mind), noisy_map(seed + 10, mind)
    ours = disp.copy()
    lr_check(ours, right, tol, inv)
    assert_same(ours, ref.lr_check(disp, right, tol, inv))
    assert np.count_nonzero(ours == inv) > np.count_nonzero(disp == inv)


def test_lr_check_keeps_consistent_pixels() -> None:
    """A fronto-parallel plane at 5 px seen by both views survives except where the right view has
    no pixel (the left 5 columns)."""
    disp = np.full((4, 20), 5 * 16, np.int16)
    right = disp.copy()
    lr_check(disp, right, 0, -16)
    assert (disp[:, 5:] == 80).all() and (disp[:, :5] == -16).all()


@pytest.mark.parametrize("mind", MIN_DISPARITIES)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_hole_fills_match_reference(seed: int, mind: int) -> None:
    inv = invalid_disparity(mind)
    disp = noisy_map(seed, mind)
    near = disp.copy()
    fill_nearest(near, inv)
    assert_same(near, ref.fill_nearest(disp, inv))
    back = disp.copy()
    fill_background(back, inv, np.empty((2, *disp.shape), np.int16))
    assert_same(back, ref.fill_background(disp, inv))
    assert not (back == inv).any() and not (near == inv).any()


@pytest.mark.parametrize("shape, valid", [((1, 1), 1.0), ((1, 9), 0.2), ((9, 1), 0.2), ((2, 3), 0.3),
                                          ((17, 23), 0.03), ((40, 31), 0.1), ((33, 64), 0.6)])
def test_background_fill_matches_the_reference_on_sparse_maps(shape: tuple[int, int], valid: float) -> None:
    """Few valid pixels: many holes see one path or none (those stay invalid), edges and single rows
    or columns, where a path leaves the map at once."""
    rng = np.random.default_rng(shape[0] * 100 + shape[1])
    for mind in (0, -40):
        inv = invalid_disparity(mind)
        disp = rng.integers(mind * 16, (mind + 64) * 16, shape).astype(np.int16)
        disp[rng.random(shape) >= valid] = inv
        back = disp.copy()
        fill_background(back, inv, np.empty((2, *shape), np.int16))
        assert_same(back, ref.fill_background(disp, inv))


def test_background_fill_takes_the_far_side_of_an_occlusion() -> None:
    """A hole between a near (40 px) and a far (10 px) surface fills from the far one."""
    d = np.full((9, 30), 10 * 16, np.int16)
    d[:, 15:] = 40 * 16
    d[:, 12:15] = -16  # the occlusion, left of the near surface
    fill_background(d, -16, np.empty((2, *d.shape), np.int16))
    assert (d[:, 12:15] == 10 * 16).all()


def test_empty_rows_stay_invalid() -> None:
    d = np.full((3, 8), -16, np.int16)
    fill_nearest(d, -16)
    fill_background(d, -16, np.empty((2, *d.shape), np.int16))
    assert (d == -16).all()


@pytest.mark.parametrize("mind", MIN_DISPARITIES)
@pytest.mark.parametrize("alpha,delta,iterations", [(128, 32, 1), (64, 8, 2), (200, 4096, 3), (256, 16, 1)])
def test_spatial_filter_matches_reference(alpha: int, delta: int, iterations: int, mind: int) -> None:
    inv = invalid_disparity(mind)
    disp = noisy_map(3, mind, holes=0.1)
    ours = disp.copy()
    spatial_filter(ours, alpha, delta, iterations, inv)
    assert_same(ours, ref.spatial(disp, alpha, delta, iterations, inv))


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (9, 1), (2, 3), (15, 40), (16, 7), (17, 23), (33, 64), (48, 5)])
def test_spatial_and_median_match_the_reference_on_any_shape(shape: tuple[int, int]) -> None:
    """Single rows and columns, and heights below, at and past the spatial filter's strips of 16
    rows (the last strip partial or whole); values near both ends of int16."""
    rng = np.random.default_rng(shape[0] * 100 + shape[1])
    inv = invalid_disparity(0)
    disp = rng.integers(-16, 32767, shape).astype(np.int16)
    disp[rng.random(shape) < 0.5] = rng.integers(32000, 32767)  # near plateaus: steps within delta
    disp[rng.random(shape) < 0.15] = inv
    ours = disp.copy()
    spatial_filter(ours, 77, 1024, 2, inv)
    assert_same(ours, ref.spatial(disp, 77, 1024, 2, inv))
    out = np.empty_like(disp)
    median_filter(disp, 3, out)
    assert_same(out, ref.median(disp, 3))


def test_spatial_filter_smooths_noise_and_keeps_edges() -> None:
    disp = noisy_map(4, 0, holes=0.0)
    ours = disp.copy()
    spatial_filter(ours, 96, 48, 2, -16)
    far = (disp != -16) & (np.arange(disp.shape[1]) < 8)[None, :]  # the far plane's valid pixels
    assert ours[far].std() < disp[far].std() / 2
    assert ours[11, 20] > 18 * 16 and ours[11, 5] < 8 * 16  # the near box stays near, the far plane far


@pytest.mark.parametrize("persistence", [0, 1, 3, 8])
def test_temporal_filter_matches_reference(persistence: int) -> None:
    frames = [noisy_map(s, 0, holes=0.3) for s in range(6)]
    state = TemporalState()
    ours = []
    for f in frames:
        out = f.copy()
        temporal_filter(out, state, 100, 24, persistence, -16)
        ours.append(out)
    for o, w in zip(ours, ref.temporal(frames, 100, 24, persistence, -16)):
        assert_same(o, w)


def test_temporal_persistence_holds_then_lets_go_and_reset_forgets() -> None:
    valid = np.full((2, 3), 80, np.int16)
    hole = np.full((2, 3), -16, np.int16)
    state = TemporalState()
    outs = []
    for f in (valid, hole, hole, hole):
        out = f.copy()
        temporal_filter(out, state, 128, 32, 2, -16)
        outs.append(out)
    assert (outs[1] == 80).all() and (outs[2] == 80).all() and (outs[3] == -16).all()
    state.reset()
    out = hole.copy()
    temporal_filter(out, state, 128, 32, 2, -16)
    assert (out == -16).all()


@pytest.mark.parametrize("size", [3, 5])
@pytest.mark.parametrize("seed", [0, 5])
def test_median_matches_reference(size: int, seed: int) -> None:
    disp = noisy_map(seed, -4)
    out = np.empty_like(disp)
    median_filter(disp, size, out)
    assert_same(out, ref.median(disp, size))


@pytest.mark.parametrize("n", [2, 3, 4])
@pytest.mark.parametrize("mind", MIN_DISPARITIES)
def test_decimation_matches_reference(n: int, mind: int) -> None:
    inv = invalid_disparity(mind)
    disp = noisy_map(6, mind, holes=0.5)
    ours = disp.copy()
    decimate(ours, n, inv)
    assert_same(ours, ref.decimate(disp, n, inv))
    assert np.unique(ours[:n, :n]).size == 1


@pytest.mark.parametrize("hole_fill", [1, 2])
def test_the_chain_runs_every_stage_in_order_as_the_reference(hole_fill: int) -> None:
    from stereocam.stereo.post import PostChain, PostParams

    p = PostParams(lr_check=1, hole_fill=hole_fill, spatial_alpha=150, spatial_delta=40, spatial_iterations=2,
                   temporal_alpha=90, median_size=5, decimation=3)
    disp, right = noisy_map(7, -4), noisy_map(8, -4)
    chain = PostChain(p, -4)
    ours = chain.run(disp, lambda: right, with_confidence=True)
    inv = invalid_disparity(-4)
    assert_same(ours, ref.chain(disp, p, inv, right))
    want = ref.confidence(ref.lr_check(disp, right, 1, inv), ours, inv)
    assert chain.confidence is not None and np.array_equal(chain.confidence, want)
    assert (want == 16).any() and (want > 16).any()  # filled holes and matched pixels


def test_confidence_without_stages_marks_invalid_and_isolated_pixels() -> None:
    from stereocam.stereo.post import PostChain, PostParams

    disp = np.full((5, 6), 80, np.int16)
    disp[0, 0] = -16
    disp[4, 5] = 400  # an outlier: no neighbour within 1 px
    chain = PostChain(PostParams())
    out = chain.run(disp, with_confidence=True)
    assert np.array_equal(out, disp) and chain.confidence is not None
    assert chain.confidence[0, 0] == 0 and chain.confidence[4, 5] == 31 and chain.confidence[2, 2] == 255
    assert np.array_equal(chain.confidence, ref.confidence(disp, disp, -16))


def test_the_chain_refuses_maps_it_cannot_read_with_the_reason() -> None:
    from stereocam.protocol.errors import ConfigError
    from stereocam.stereo.post import PostChain, PostParams
    from stereocam.stereo.post.chain import postprocess
    from stereocam.stereo.sgm_params import SGMParams
    d = np.full((40, 64), 48, np.int16)
    lr = PostChain(PostParams(lr_check=0))
    # a right view of another shape would be read out of bounds
    with pytest.raises(ValueError, match="right view's disparity is 64x1"):
        lr.run(d, lambda: np.full((1, 64), 48, np.int16))
    with pytest.raises(ValueError, match="right view's disparity must be a numpy array"):
        lr.run(d, lambda: None)
    med = PostChain(PostParams(median_size=3))
    for bad, word in ((np.full((4, 4), np.nan, np.float32), "int16.*float32"),
                      (d.astype(np.int32) * 1000, "outside int16"),
                      (np.zeros((3, 4, 2), np.int16), "2-D"),
                      (np.zeros((0, 5), np.int16), "empty"),
                      (d.tolist(), "numpy array")):
        with pytest.raises(ValueError, match=word):
            med.run(bad)
    np.testing.assert_array_equal(med.run(d.astype(np.int32)), med.run(d))  # integers that fit
    with pytest.raises(ConfigError, match="min_disparity=3000"):
        PostChain(PostParams(), min_disparity=3000)
    with pytest.raises(ConfigError, match="min_disparity must be an int"):
        PostChain(PostParams(), min_disparity="0")
    with pytest.raises(ValueError, match="params must be PostParams, got dict"):
        PostChain({"hole_fill": 2})
    img = np.zeros((10, 64), np.uint8)
    with pytest.raises(ValueError, match="differ in shape"):
        postprocess(np.full((300, 64), 48, np.int16), img, PostParams(lr_check=64), img,
                    SGMParams(num_disparities=16))
