"""Median filter of side 3 or 5 over the disparity codes (invalid ones included: a hole whose window
is mostly valid closes); the image edge is replicated."""
from __future__ import annotations

import numba as nb
import numpy as np

from ..jit import KERNEL


@nb.njit(inline="always")
def _med3(a: np.int16, b: np.int16, c: np.int16) -> np.int16:
    return max(min(a, b), min(max(a, b), c))


@nb.njit(**KERNEL)
def _median3(padded: np.ndarray, out: np.ndarray) -> None:
    """3 x 3: each column's three values sorted, then the median of (the largest low, the middle
    middle, the smallest high) of three neighbouring columns, which is the median of the nine."""
    h, w = out.shape
    for y in range(h):
        lo = np.empty(w + 2, np.int16)
        mid = np.empty(w + 2, np.int16)
        hi = np.empty(w + 2, np.int16)
        for x in range(w + 2):
            a, b, c = padded[y, x], padded[y + 1, x], padded[y + 2, x]
            lo[x] = min(a, b, c)
            hi[x] = max(a, b, c)
            mid[x] = _med3(a, b, c)
        for x in range(w):
            out[y, x] = _med3(max(lo[x], lo[x + 1], lo[x + 2]), _med3(mid[x], mid[x + 1], mid[x + 2]),
                              min(hi[x], hi[x + 1], hi[x + 2]))


@nb.njit(**KERNEL)
def _median(padded: np.ndarray, size: int, out: np.ndarray) -> None:
    """Any odd size: each column's ``size`` values sorted once per row, then the window's median
    picked by merging its ``size`` sorted columns up to the middle element."""
    h, w = out.shape
    cols = np.empty((w + size - 1, size), np.int16)
    heads = np.empty(size, np.int64)
    middle = size * size // 2
    for y in range(h):
        for x in range(w + size - 1):
            for i in range(size):  # insertion sort of one column
                v = padded[y + i, x]
                j = i
                while j > 0 and cols[x, j - 1] > v:
                    cols[x, j] = cols[x, j - 1]
                    j -= 1
                cols[x, j] = v
        for x in range(w):
            heads[:] = 0
            last = np.int16(0)
            for _ in range(middle + 1):
                best = -1
                for c in range(size):
                    if heads[c] < size and (best < 0 or cols[x + c, heads[c]] < cols[x + best, heads[best]]):
                        best = c
                last = cols[x + best, heads[best]]
                heads[best] += 1
            out[y, x] = last


def median_filter(disp: np.ndarray, size: int, out: np.ndarray) -> None:
    """out = the median of each size x size window of disp (edge replicated)."""
    padded = np.pad(disp, size // 2, mode="edge")
    if size == 3:
        _median3(padded, out)
    else:
        _median(padded, size, out)
