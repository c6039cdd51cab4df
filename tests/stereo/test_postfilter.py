"""The speckle filter (postfilter: runs united across rows), whole and in the row bands the
5-path SGM runs it in, equals cv2.filterSpeckles at every split row."""
from __future__ import annotations

import numpy as np
import pytest

from stereocam.stereo.postfilter import clear_seam, filter_speckles, join_seam, label_band

cv2 = pytest.importorskip("cv2")
INV = -16


def split_filter(img: np.ndarray, top: int, max_size: int, max_diff: int) -> None:
    h, w = img.shape
    labels = np.empty((h, w), np.int32)
    stack = np.empty((h * w, 2), np.int32)
    size, parent = np.empty(h * w + 1, np.int32), np.empty(h * w + 1, np.int32)
    rtype = np.zeros(h * w + 1, np.uint8)
    bands = [(0, top, top - 1 if top < h else -1), (top, h, top)]
    for r0, r1, edge in bands[::-1]:  # the order the halves finish in does not matter
        label_band(img, r0, r1, edge, INV, max_size, max_diff, labels, stack, size, parent,
                   rtype)
    if top < h:
        join_seam(img, top, INV, max_diff, labels, size, parent)
        clear_seam(img, top, INV, max_size, labels, stack, size, parent)


@pytest.mark.parametrize("seed", range(4))
def test_bands_equal_cv2_filter_speckles(seed: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = 17, 23
    img = (rng.integers(0, 4, (h, w)) * 16).astype(np.int16)
    img[rng.random((h, w)) < 0.2] = INV
    img[:, 5] = 32  # one region across every seam
    for max_size in (0, 3, 12, 60):
        want = img.copy()
        cv2.filterSpeckles(want, INV, max_size, 16)
        for top in range(1, h + 1):
            got = img.copy()
            split_filter(got, top, max_size, 16)
            assert np.array_equal(got, want), (max_size, top)


def scratch(h: int, w: int) -> tuple[np.ndarray, ...]:
    n = h * w
    return (np.empty((h, w), np.int32), np.empty((n, 2), np.int32), np.empty(n + 1, np.int32),
            np.empty(n + 1, np.int32), np.zeros(n + 1, np.uint8))


def speckle_cases(seed: int):
    """Disparity maps as the engines make them: smooth ramps with noise, holes, blocks and a
    checkerboard in which every pixel is its own run (the most runs a band can have)."""
    rng = np.random.default_rng(seed)
    for i in range(16):  # the last four wide: runs across many of the filter's 8-pixel words
        h, w = int(rng.integers(1, 40)), int(rng.integers(1, 70) if i < 12 else rng.integers(100, 300))
        ramp = np.cumsum(rng.integers(-1, 2, (h, w)), axis=1) * int(rng.integers(4, 24))
        img = (ramp + rng.integers(0, 3, (h, w)) * 16).astype(np.int16)
        img[rng.random((h, w)) < rng.random() * 0.4] = INV
        yield img
    yy, xx = np.mgrid[:9, :13]
    yield (((yy + xx) % 2) * 160).astype(np.int16)
    for i in range(12):  # blocks of a few levels: rows of few runs, regions joined at single
        # pixels; levels 24 apart join a neighbour level at max_diff 32, not the next one
        h, w = int(rng.integers(2, 50)), int(rng.integers(8, 300))
        bh, bw = int(rng.integers(1, 6)), int(rng.integers(1, 12))
        coarse = rng.integers(0, 4, (h // bh + 1, w // bw + 1)) * (48 if i % 2 else 24)
        img = np.repeat(np.repeat(coarse, bh, 0), bw, 1)[:h, :w].astype(np.int16)
        img[rng.random((h, w)) < 0.02] = INV
        yield img


@pytest.mark.parametrize("seed", range(3))
def test_whole_image_and_bands_equal_cv2_filter_speckles_on_engine_like_maps(seed: int) -> None:
    for img in speckle_cases(seed):
        h, w = img.shape
        for max_size, max_diff in ((0, 16), (2, 0), (7, 32), (40, 16), (10_000, 64)):
            want = img.copy()
            cv2.filterSpeckles(want, INV, max_size, max_diff)
            got = img.copy()
            filter_speckles(got, INV, max_size, max_diff, *scratch(h, w))
            assert np.array_equal(got, want), (img.shape, max_size, max_diff)
            for top in {1, h // 2 + 1, h}:
                got = img.copy()
                split_filter(got, top, max_size, max_diff)
                assert np.array_equal(got, want), (img.shape, max_size, max_diff, top)


def flags_reference(row: np.ndarray, above: np.ndarray | None, new_val: int, max_diff: int) -> np.ndarray:
    """postfilter._row_flags' definition in numpy (int64, so no difference overflows)."""
    v = row.astype(np.int64)
    ok = v != new_val
    far = lambda a, b: np.abs(a - b) > max_diff  # noqa: E731
    s, e = ok.copy(), ok.copy()
    s[1:] &= (v[:-1] == new_val) | far(v[1:], v[:-1])
    e[:-1] &= (v[1:] == new_val) | far(v[1:], v[:-1])
    k = np.zeros_like(ok)
    if above is not None:
        u = above.astype(np.int64)
        uk = u != new_val
        j = ok & uk & ~far(v, u)
        su = uk.copy()
        su[1:] &= (u[:-1] == new_val) | far(u[1:], u[:-1])
        jp = np.concatenate([[False], j[:-1]])
        k = j & (~jp | s | su)
    return (s * 1 | e * 2 | k * 4).astype(np.uint8)


@pytest.mark.parametrize("seed", range(3))
def test_row_flags_vector_and_scalar_paths_match_their_definition(seed: int) -> None:
    """The per-pixel flags the labelling reads, made a register at a time with a scalar
    first pixel and tail, on rows of every length around the register width, extreme int16
    values (the vector absolute difference must not overflow) and max_diff at and past the
    vector path's range."""
    from stereocam.stereo.postfilter import _row_flags

    rng = np.random.default_rng(seed)
    for w in [1, 2, 3, *rng.integers(4, 200, 12)]:
        w = int(w)
        pair = rng.choice(np.array([INV, -32768, 32767, 0, 16, 40, 70, 100], np.int16), (2, w))
        pair[:, rng.random(w) < 0.5] = rng.integers(0, 120, (2, w))[:, :1]  # some runs
        flat = pair.ravel()
        flags = np.zeros((w + 7) & ~7, np.uint8)
        for max_diff in (0, 16, 32, 65535, 70000, -1):
            for above in (False, True):
                flags[:] = 0xFF
                _row_flags(flat, w, 0 if above else -1, w, INV, max_diff, flags)
                want = flags_reference(pair[1], pair[0] if above else None, INV, max_diff)
                assert np.array_equal(flags[:w], want), (w, max_diff, above)
