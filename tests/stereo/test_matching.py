"""Differential tests: stereocam.stereo block matching vs cv2.StereoBM (the oracle), zero differing pixels."""
from __future__ import annotations

import itertools

import numba
import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from stereocam.stereo import Matcher, MatchParams, match  # noqa: E402
from stereocam.tools.bench.stereobm_oracle import opencv_stereobm as cv_stereo_bm  # noqa: E402


def scene(h: int, w: int, shift: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Random texture seen with a known shift, plus a nearer plane and a flat patch."""
    rng = np.random.default_rng(seed)
    pad = 2 * shift + 8
    base = rng.integers(0, 256, (h, w + 2 * pad), dtype=np.uint8)
    base = cv2.GaussianBlur(base, (3, 3), 0)
    right = base[:, pad:pad + w].copy()
    left = base[:, pad - shift:pad - shift + w].copy()
    y0, y1, x0, x1 = h // 4, h // 2, w // 3, w // 2
    left[y0:y1, x0:x1] = base[y0:y1, pad - 2 * shift + x0:pad - 2 * shift + x1]
    left[h - h // 5:, : w // 4] = 128  # textureless patch (texture / uniqueness rejects)
    right[h - h // 5:, : w // 4] = 128
    return left, right


def assert_same(left: np.ndarray, right: np.ndarray, p: MatchParams) -> np.ndarray:
    ours = match(left, right, p)
    ref = cv_stereo_bm(p).compute(left, right)
    assert ours.dtype == np.int16 and ours.shape == left.shape
    diff = np.argwhere(ours != ref)
    assert diff.size == 0, (f"{len(diff)} pixels differ for {p}; first (y, x, ours, cv2): "
                            + str([(y, x, ours[y, x], ref[y, x]) for y, x in diff[:5]]))
    return ours


SHAPES = [(64, 96), (97, 151), (120, 160), (81, 203), (111, 127)]
GRID = list(itertools.product(
    ["xsobel", "normalized"], [5, 9, 15, 21], [16, 32, 48, 64, 80, 112, 128], [0, -7, 5],
    [(10, 15), (0, 0), (25, 5)], [False, True], [False, True]))


def _grid_case(i: int):
    pf, bs, nd, md, (tt, ur), lr, sp = GRID[i]
    h, w = SHAPES[i % len(SHAPES)]
    while w < nd + max(md, 0) + bs + 8:
        w += 64  # keep some valid columns for the large ranges
    kw = dict(pre_filter_type=pf, block_size=bs, num_disparities=nd, min_disparity=md,
              texture_threshold=tt, uniqueness_ratio=ur,
              pre_filter_size=(5, 9, 13)[i % 3], pre_filter_cap=(31, 15, 31, 63)[i % 4])
    if lr:
        kw["disp12_max_diff"] = i % 3
    if sp:
        kw.update(speckle_window_size=10 + i % 40, speckle_range=(1, 16, 32)[i % 3])
    if kw["pre_filter_cap"] == 63 and lr:
        kw["pre_filter_cap"] = 31  # OpenCV bug with 32-bit costs + left-right check, see below
    return (h, w), MatchParams(**kw), 3 + i % 9


@pytest.mark.parametrize("i", range(0, len(GRID), 11))
def test_grid_vs_opencv(i: int) -> None:
    shape, p, shift = _grid_case(i)
    left, right = scene(*shape, shift=shift + max(p.min_disparity, 0), seed=i)
    assert_same(left, right, p)


@pytest.mark.parametrize("kw", [
    dict(num_disparities=16, block_size=9, min_disparity=-30),  # whole range negative
    dict(num_disparities=16, block_size=9, min_disparity=-15),  # N - 1 + min = 0
    dict(num_disparities=16, block_size=9, min_disparity=-16),
    dict(num_disparities=32, block_size=25, pre_filter_cap=63),  # 32-bit accumulators
    dict(num_disparities=112, block_size=23, min_disparity=-3),  # 32-bit, 64+32+16 lanes
    dict(num_disparities=80, block_size=5, pre_filter_cap=63, uniqueness_ratio=40),
    dict(num_disparities=32, block_size=41, pre_filter_cap=40, uniqueness_ratio=5),
    dict(num_disparities=32, block_size=21, pre_filter_type="normalized", pre_filter_size=31),
    dict(num_disparities=16, block_size=9, min_disparity=7, texture_threshold=0,
         uniqueness_ratio=0),  # OpenCV writes past the row end into row H - r
    dict(num_disparities=16, block_size=9, min_disparity=3, texture_threshold=0,
         uniqueness_ratio=0, disp12_max_diff=0),
    dict(num_disparities=32, block_size=11, speckle_window_size=400, speckle_range=2,
         texture_threshold=0, uniqueness_ratio=0),
    dict(num_disparities=32, block_size=7, pre_filter_size=255, pre_filter_type="normalized"),
])
def test_edge_cases_vs_opencv(kw: dict) -> None:
    left, right = scene(97, 151, shift=6, seed=1)
    assert_same(left, right, MatchParams(**kw))


def test_wide_costs_with_lr_check_differ_only_in_lr_decisions() -> None:
    """OpenCV bug: with 32-bit costs (cap > 31 or block > 21) its left-right check reads the
    16-bit cost buffer that the matcher filled through an int pointer, so it compares garbage
    costs. We run the intended check; every pixel where we differ must be one the check
    invalidated on one side only, with the value both give without the check on the other."""
    left, right = scene(97, 151, shift=6, seed=0)
    for kw in (dict(num_disparities=32, block_size=25), dict(num_disparities=32, block_size=9,
                                                             pre_filter_cap=63)):
        base = MatchParams(**kw)
        p = MatchParams(**kw, disp12_max_diff=1)
        ours, ref = match(left, right, p), cv_stereo_bm(p).compute(left, right)
        no_lr = match(left, right, base)
        diff = ours != ref
        assert np.array_equal(no_lr, cv_stereo_bm(base).compute(left, right))
        inv = p.invalid_value
        one_side = ((ours == inv) & (ref == no_lr)) | ((ref == inv) & (ours == no_lr))
        assert np.all(one_side[diff])
        assert np.count_nonzero(ours != no_lr) > 0  # the check does invalidate pixels


def test_known_shift_recovered() -> None:
    left, right = scene(120, 160, shift=9, seed=3)
    d = match(left, right, MatchParams(num_disparities=32, block_size=9))
    bg = d[10:25, 60:150]  # background plane, away from the nearer plane
    assert np.mean(np.abs(bg - 9 * 16) <= 4) > 0.9
    near = d[35:55, 60:75]
    assert np.mean(np.abs(near - 18 * 16) <= 8) > 0.8


def test_oracle_is_sensitive() -> None:
    """The comparison can fail: a different parameter set gives a different map."""
    left, right = scene(97, 151, shift=6, seed=2)
    a = match(left, right, MatchParams(num_disparities=32, block_size=9))
    b = cv_stereo_bm(MatchParams(num_disparities=32, block_size=11)).compute(left, right)
    assert np.count_nonzero(a != b) > 100


@pytest.fixture(scope="module")
def motorcycle() -> tuple[np.ndarray, np.ndarray]:
    data = pytest.importorskip("skimage.data")
    try:
        left, right, _ = data.stereo_motorcycle()
    except Exception as exc:  # pragma: no cover - data not available offline
        pytest.skip(f"Motorcycle pair unavailable: {exc}")
    return (cv2.cvtColor(left, cv2.COLOR_RGB2GRAY), cv2.cvtColor(right, cv2.COLOR_RGB2GRAY))


@pytest.mark.parametrize("kw", [
    dict(),  # OpenCV defaults, full size
    dict(num_disparities=128, block_size=15, disp12_max_diff=1, speckle_window_size=100,
         speckle_range=32),
    dict(num_disparities=64, block_size=9, pre_filter_type="normalized", min_disparity=-3),
])
def test_motorcycle_full_size(motorcycle, kw: dict) -> None:
    left, right = motorcycle
    d = assert_same(left, right, MatchParams(**kw))
    assert np.count_nonzero(d >= 0) > 0.3 * d.size


def test_motorcycle_crops(motorcycle) -> None:
    left, right = motorcycle
    for k, (y, x, h, w) in enumerate([(101, 203, 127, 251), (0, 0, 99, 333), (300, 400, 151, 201)]):
        p = MatchParams(num_disparities=(32, 64, 48)[k], block_size=(7, 11, 17)[k],
                        uniqueness_ratio=(5, 15, 0)[k], disp12_max_diff=(-1, 2, 0)[k])
        assert_same(left[y:y + h, x:x + w], right[y:y + h, x:x + w], p)


def test_matcher_reuses_buffers_and_threads_agree() -> None:
    p = MatchParams(num_disparities=32, block_size=9, disp12_max_diff=1, speckle_window_size=30,
                    speckle_range=16)
    m = Matcher((97, 151), p)
    vs = m.vs
    maps = []
    for seed in (4, 5, 4):
        left, right = scene(97, 151, shift=7, seed=seed)
        maps.append(m.match(left, right))
        assert m.vs is vs
    np.testing.assert_array_equal(maps[0], maps[2])
    assert np.any(maps[0] != maps[1])
    left, right = scene(97, 151, shift=7, seed=4)
    for ns in (1, 3, 5):
        np.testing.assert_array_equal(Matcher((97, 151), p, nstripes=ns).match(left, right),
                                      maps[0])
    n = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        np.testing.assert_array_equal(match(left, right, p), maps[0])
    finally:
        numba.set_num_threads(n)


def test_non_contiguous_input() -> None:
    left, right = scene(97, 302, shift=6, seed=6)
    p = MatchParams(num_disparities=32, block_size=9)
    assert_same(left[:, ::2], right[:, ::2], p)


@pytest.mark.parametrize("kw, word", [
    (dict(num_disparities=0), "num_disparities"),
    (dict(num_disparities=24), "num_disparities"),
    (dict(num_disparities=-16), "num_disparities"),
    (dict(block_size=4), "block_size"),
    (dict(block_size=3), "block_size"),
    (dict(block_size=257), "block_size"),
    (dict(pre_filter_size=8), "pre_filter_size"),
    (dict(pre_filter_size=3), "pre_filter_size"),
    (dict(pre_filter_size=257), "pre_filter_size"),
    (dict(pre_filter_cap=0), "pre_filter_cap"),
    (dict(pre_filter_cap=64), "pre_filter_cap"),
    (dict(pre_filter_type="sobel"), "pre_filter_type"),
    (dict(texture_threshold=-1), "texture_threshold"),
    (dict(uniqueness_ratio=-1), "uniqueness_ratio"),
    (dict(speckle_window_size=-1), "speckle_window_size"),
    (dict(speckle_range=-1), "speckle_range"),
    (dict(block_size=9.0), "block_size"),
    (dict(min_disparity=3000), "min_disparity"),
])
def test_bad_params(kw: dict, word: str) -> None:
    with pytest.raises(ValueError, match=word):
        MatchParams(**kw)


def test_bad_images() -> None:
    img = np.zeros((64, 96), np.uint8)
    p = MatchParams(num_disparities=16, block_size=9)
    with pytest.raises(ValueError, match="differ in shape"):
        match(img, np.zeros((64, 95), np.uint8), p)
    with pytest.raises(ValueError, match="uint8, got uint16: scale it to 8 bits"):
        match(img.astype(np.uint16), img.astype(np.uint16), p)
    with pytest.raises(ValueError, match="uint8, got float32$"):
        match(img.astype(np.float32), img, p)
    with pytest.raises(ValueError, match=r"2-D \(grey\), got shape \(64, 96, 3\): turn colour grey"):
        match(np.zeros((64, 96, 3), np.uint8), np.zeros((64, 96, 3), np.uint8), p)
    with pytest.raises(ValueError, match=r"right image must be 2-D \(grey\), got shape \(1, 64, 96\)$"):
        match(img, img[None], p)
    with pytest.raises(ValueError, match="numpy array"):
        match(img.tolist(), img, p)
    with pytest.raises(ValueError, match="block_size"):  # window larger than the image
        match(img[:9], img[:9], p)
    with pytest.raises(ValueError, match="leaves no column"):  # disparity range wider than the image
        match(img[:, :20], img[:, :20], p)
    with pytest.raises(ValueError, match="leaves no column"):
        match(img[:, :24], img[:, :24], MatchParams(num_disparities=16, block_size=9,
                                                    min_disparity=10))
    with pytest.raises(ValueError, match="shape"):
        Matcher((64, 96), p).match(img[:, :90], img[:, :90])


def test_opencv_rejects_what_we_reject() -> None:
    """Where we raise for geometry, OpenCV raises or has no valid pixel to give.

    (Between those cases, e.g. 64x20 with 16 disparities and block 9, OpenCV returns the
    uninitialised output buffer because its valid region is empty; we raise there too.)
    """
    img = np.random.default_rng(0).integers(0, 255, (64, 15), dtype=np.uint8)
    p = MatchParams(num_disparities=16, block_size=9)
    out = cv_stereo_bm(p).compute(img, img)
    assert np.all(out == p.invalid_value)
    with pytest.raises(ValueError, match="leaves no column"):
        match(img, img, p)
    with pytest.raises(cv2.error):
        cv_stereo_bm(p).compute(img[:9], img[:9])


@pytest.mark.parametrize("shape", [(30,), None, "ab", (30, 60, 3), (30.7, 60.9), (True, 60)])
def test_a_shape_that_is_not_two_ints_is_refused(shape) -> None:
    from stereocam.stereo import SGMMatcher, SGMParams
    with pytest.raises(ValueError, match=r"shape must be \(height, width\)"):
        Matcher(shape, MatchParams(num_disparities=16))
    with pytest.raises(ValueError, match=r"shape must be \(height, width\)"):
        SGMMatcher(shape, SGMParams(num_disparities=16))
    with pytest.raises(ValueError, match="nstripes"):
        Matcher((30, 60), MatchParams(num_disparities=16), nstripes=2.5)
