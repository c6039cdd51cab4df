"""Semi-global matching: the numba engine is bit-exact with the numpy reference
(tests/support/sgm_reference.py) on random images, simulator scenes and Middlebury Motorcycle."""
from __future__ import annotations

import numba
import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from stereocam.stereo import (  # noqa: E402
    MatchParams, SGMMatcher, SGMParams, match, sgm_geometry)

from tests.support import sgm_reference as ref  # noqa: E402


def pair(h: int, w: int, shift: int, seed: int, blur: bool = True):
    """Random texture seen with a shift, a nearer box, a flat patch and some noise."""
    rng = np.random.default_rng(seed)
    pad = 2 * shift + 8
    base = rng.integers(0, 256, (h, w + 2 * pad), dtype=np.uint8)
    if blur:
        base = cv2.GaussianBlur(base, (3, 3), 0)
    right = base[:, pad:pad + w].copy()
    left = base[:, pad - shift:pad - shift + w].copy()
    y0, y1, x0, x1 = h // 4, h // 2, w // 2, 3 * w // 4
    left[y0:y1, x0:x1] = base[y0:y1, pad - 2 * shift + x0:pad - 2 * shift + x1]
    left[h - h // 5:, w // 2:] = 90
    right[h - h // 5:, w // 2:] = 90
    noise = rng.integers(-2, 3, left.shape)
    left = np.clip(left.astype(int) + noise, 0, 255).astype(np.uint8)
    return left, right


def assert_same(left: np.ndarray, right: np.ndarray, p: SGMParams) -> np.ndarray:
    ours = SGMMatcher(left.shape, p).match(left, right)
    want = ref.sgm(left, right, p)
    assert ours.dtype == np.int16 and ours.shape == left.shape
    diff = np.argwhere(ours != want)
    assert diff.size == 0, (f"{len(diff)} pixels differ for {p}; first (y, x, ours, ref): "
                            + str([(y, x, ours[y, x], want[y, x]) for y, x in diff[:5]]))
    valid = ours != p.invalid_value
    assert valid.any()
    return ours


EDGES = [
    dict(),
    dict(uniqueness_ratio=10, lr_max_diff=1),
    dict(uniqueness_ratio=1, lr_max_diff=0, p2_adapt=0),
    dict(uniqueness_ratio=99, lr_max_diff=3, speckle_window_size=0),
    dict(p1=0, p2=0, p2_adapt=0),  # no smoothness: winner-take-all on census costs
    dict(p1=40, p2=40, p2_adapt=1),  # p1 == p2; P2 adapts down to p1
    dict(p1=255, p2=20, uniqueness_ratio=100),  # p1 > p2 (saturating); largest p1
    dict(p1=5, p2=255 - 62),  # largest P2 for a 9x7 census (path costs reach 255)
    dict(census_width=3, census_height=1, p2=253),
    dict(census_width=1, census_height=3, lr_max_diff=2),
    dict(census_width=13, census_height=5),  # 64 comparison bits
    dict(census_width=5, census_height=5, p2_adapt=1000, uniqueness_ratio=15),
    dict(min_disparity=-9, num_disparities=32, lr_max_diff=1),
    dict(min_disparity=5, num_disparities=16, uniqueness_ratio=5),
    dict(min_disparity=-20, num_disparities=16),  # the whole range negative
    dict(num_disparities=48, speckle_window_size=20, speckle_range=16),
    dict(num_disparities=80, lr_max_diff=1),  # 64 + 16 lanes
    dict(census_margin=0),  # plain census
    dict(census_margin=3, census_width=3, census_height=1),  # a window one row high
    dict(census_margin=255, speckle_window_size=0),  # every bit masked: cost 0 everywhere
    dict(p1_ground_percent=48),  # the ground step cheaper on vertical/diagonal paths
    dict(p1=255, p2=20, p1_ground_percent=0, lr_max_diff=1),  # a free ground step; saturating
    dict(p1=40, p2=60, p1_ground_percent=75, min_disparity=-9, num_disparities=32),
]
SHAPES = [(23, 97), (37, 121), (50, 131), (31, 160)]


@pytest.mark.parametrize("paths", [4, 5, 8])
@pytest.mark.parametrize("i", range(len(EDGES)))
def test_random_pairs_bit_exact(i: int, paths: int) -> None:
    p = SGMParams(**{"num_disparities": 32, **EDGES[i], "paths": paths})
    h, w = SHAPES[i % len(SHAPES)]
    while sgm_geometry(h, w + 20, p).cols < 40:
        w += 32
    left, right = pair(h, w, 4 + i % 7 + max(p.min_disparity, 0), seed=i, blur=i % 2 == 0)
    assert_same(left, right, p)


def test_raw_noise_and_flat_images() -> None:
    rng = np.random.default_rng(7)
    a = rng.integers(0, 256, (29, 77), dtype=np.uint8)
    b = rng.integers(0, 256, (29, 77), dtype=np.uint8)
    assert_same(a, b, SGMParams(num_disparities=16, uniqueness_ratio=5, lr_max_diff=1,
                                speckle_window_size=0))
    flat = np.full((17, 50), 77, np.uint8)
    p = SGMParams(num_disparities=16, speckle_window_size=0)
    out = SGMMatcher(flat.shape, p).match(flat, flat)
    np.testing.assert_array_equal(out, ref.sgm(flat, flat, p))


@pytest.fixture(scope="module")
def motorcycle():
    skimage_data = pytest.importorskip("skimage.data")
    left, right, _ = skimage_data.stereo_motorcycle()
    return [cv2.cvtColor(im, cv2.COLOR_RGB2GRAY) for im in (left, right)]


@pytest.fixture(scope="module")
def motorcycle_small(motorcycle):
    return [cv2.resize(g, (183, 123), interpolation=cv2.INTER_AREA) for g in motorcycle]


@pytest.mark.slow
@pytest.mark.parametrize("kw", [dict(), dict(paths=4, uniqueness_ratio=10, lr_max_diff=1),
                                dict(paths=5)])
def test_full_size_motorcycle_bit_exact(motorcycle, kw) -> None:
    """Middlebury Motorcycle at 741x500 with 128 disparities, as the benchmark runs it."""
    left, right = motorcycle
    assert_same(left, right, SGMParams(num_disparities=128, **kw))


@pytest.mark.parametrize("kw", [dict(paths=8), dict(paths=4, uniqueness_ratio=5, lr_max_diff=1),
                                dict(paths=5, uniqueness_ratio=10, lr_max_diff=1),
                                dict(min_disparity=-3, census_width=7, census_height=5)])
def test_motorcycle_bit_exact(motorcycle_small, kw) -> None:
    left, right = motorcycle_small
    assert_same(left, right, SGMParams(num_disparities=32, **kw))


@pytest.fixture(scope="module")
def sim_pair():
    from stereocam.tools.bench.sgm import sim_scene
    left, right, truth = sim_scene(320, 240, scene="lab", seed=5)
    return left[5:152, 3:290], right[5:152, 3:290], truth[5:152, 3:290]


@pytest.mark.parametrize("paths", [4, 5, 8])
def test_simulator_scene_bit_exact_and_accurate(sim_pair, paths: int) -> None:
    left, right, truth = sim_pair
    p = SGMParams(num_disparities=48, paths=paths, lr_max_diff=1)
    ours = assert_same(left, right, p)
    g = sgm_geometry(*left.shape, p)
    valid = ours[:, g.x0:] != p.invalid_value
    err = np.abs(ours[:, g.x0:] / 16.0 - truth[:, g.x0:])
    assert valid.mean() > 0.8
    assert np.mean(err[valid] <= 1.0) > 0.9  # the simulator's truth, not the reference


def test_output_contract_and_match_api() -> None:
    left, right = pair(40, 200, 6, seed=3)
    p = SGMParams(num_disparities=16, min_disparity=2)
    out = match(left, right, p)
    assert out.dtype == np.int16 and out.shape == left.shape
    assert p.invalid_value == 16
    assert np.all(out[:, :sgm_geometry(40, 200, p).x0] == p.invalid_value)
    inner = out[2:-2, 40:]
    assert np.median(inner[inner != p.invalid_value]) == pytest.approx(6 * 16, abs=8)
    assert np.array_equal(match(left, right, SGMParams(num_disparities=128)),
                          SGMMatcher(left.shape, SGMParams()).match(left, right))
    bm = match(left, right, MatchParams(num_disparities=16, block_size=9))
    assert not np.array_equal(bm, out)  # the block matcher still answers MatchParams


def test_left_border_is_matched() -> None:
    """The columns left of num_disparities - 1, where the larger disparities point outside the
    right image, get the scene's disparity (cv2.StereoSGBM leaves them invalid)."""
    left, right = pair(40, 200, 6, seed=4)
    p = SGMParams(num_disparities=32)
    out = SGMMatcher(left.shape, p).match(left, right)
    border = out[2:-2, 8:p.num_disparities - 1] / 16.0  # right pixel in the image from x = 6
    assert np.mean(np.abs(border - 6) <= 1) > 0.9


@pytest.mark.parametrize("paths", [4, 5, 8])
@pytest.mark.parametrize("shift", [8, 20])
def test_columns_whose_match_left_the_right_image_get_the_scene_carried_in(paths: int, shift: int) -> None:
    """Left of x = shift the scene's right pixel is outside the right image: no cost can find it,
    the paths from the right carry it in. Those out-of-image disparities cost params.outside_cost
    (3/8 of the census bits); at the largest cost (all bits) 0-6 % of these pixels came out right."""
    left, right = pair(40, 200, shift, seed=6)
    p = SGMParams(num_disparities=32, paths=paths)
    assert p.outside_cost == 12 and p.max_cost == 32
    hidden = SGMMatcher(left.shape, p).match(left, right)[2:-2, 2:shift] / 16.0
    assert np.mean(np.abs(hidden - shift) <= 1) > 0.9


@pytest.mark.parametrize("paths", [8, 5])
def test_thread_count_and_reuse_do_not_change_output(paths: int) -> None:
    """Two threads: two path groups (8) or rows taken in turn, each waiting on the row above (5)."""
    a = pair(45, 150, 5, seed=11)
    b = pair(45, 150, 9, seed=12)
    p = SGMParams(num_disparities=32, uniqueness_ratio=5, lr_max_diff=1, paths=paths)
    m = SGMMatcher(a[0].shape, p)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = [m.match(*a), m.match(*b)]
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        two = [m.match(*b), m.match(*a)]
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(one[0], two[1]) and np.array_equal(one[1], two[0])
    assert np.array_equal(one[0], ref.sgm(*a, p))


@pytest.mark.parametrize("kw, msg", [
    (dict(num_disparities=24), "multiple of 16"),
    (dict(census_width=8), "census window"),
    (dict(census_width=11, census_height=7, census_sparse=False), "census window"),  # 76 bits
    (dict(census_width=13, census_height=11), "census window .*sparse"),  # 71 of the sparse's
    (dict(census_sparse=1), "census_sparse must be True or False"),
    (dict(census_width=200001, census_height=200001), "census window"),  # counted, not listed
    (dict(paths=6), "paths"),
    (dict(p1=256), "p1: sgm_p1=256 outside 0..255"),
    (dict(p2=-1), "p2 -1 out of range"),
    (dict(p2=194, census_sparse=False), "p2 194 out of range"),  # 62 bits + 194 > 255
    (dict(p2=224), "p2 224 out of range"),  # the sparse census's 32 bits + 224 > 255
    (dict(census_width=3, census_height=1, p2=254), "p2 254 out of range"),
    (dict(uniqueness_ratio=-1), "uniqueness_ratio"),
    (dict(speckle_range=-1), "speckle_range"),
    (dict(p1=1.5), "must be an int"),
    (dict(min_disparity=-2100), "min_disparity=-2100 outside"),
    (dict(census_margin=-2), "census_margin must be -1"),
    (dict(census_margin=256), "census_margin must be -1 .* 0..255, got 256"),
    (dict(census_margin=2.0), "census_margin"),
    (dict(p1_ground_percent=101), "p1_ground_percent must be 0..100, got 101"),
    (dict(p1_ground_percent=-1), "p1_ground_percent"),
    (dict(p2_adapt=2 ** 62), r"p2_adapt must be 0..1048576"),  # p2 * p2_adapt past int64
    (dict(p2_adapt=-1), "p2_adapt"),
    (dict(p2_adapt=2.5), "p2_adapt"),
])
def test_bad_params(kw, msg) -> None:
    with pytest.raises(ValueError, match=msg):
        SGMParams(**kw)


def test_bad_inputs() -> None:
    img = np.zeros((20, 40), np.uint8)
    with pytest.raises(ValueError, match="leaves no column of width 40"):
        SGMMatcher(img.shape, SGMParams(num_disparities=48))
    m = SGMMatcher(img.shape, SGMParams(num_disparities=16))
    with pytest.raises(ValueError, match="differs"):
        m.match(np.zeros((21, 40), np.uint8), np.zeros((21, 40), np.uint8))
    with pytest.raises(ValueError, match="uint8"):
        m.match(img.astype(np.float32), img)
    with pytest.raises(ValueError, match="SGMParams"):
        SGMMatcher(img.shape, MatchParams())
