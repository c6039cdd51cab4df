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
    for _ in range(12):
        h, w = int(rng.integers(1, 40)), int(rng.integers(1, 70))
        ramp = np.cumsum(rng.integers(-1, 2, (h, w)), axis=1) * int(rng.integers(4, 24))
        img = (ramp + rng.integers(0, 3, (h, w)) * 16).astype(np.int16)
        img[rng.random((h, w)) < rng.random() * 0.4] = INV
        yield img
    yy, xx = np.mgrid[:9, :13]
    yield (((yy + xx) % 2) * 160).astype(np.int16)


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
