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
def _sort_columns(above: np.ndarray, row: np.ndarray, below: np.ndarray, s: np.ndarray) -> None:
    """s[0 / 1 / 2, 1 + x]: the smallest / middle / largest of column x's three values; the ends
    replicated into s[:, 0] and s[:, w + 1] (the image edge). One scratch array: few enough arrays
    for the vectoriser's overlap checks."""
    w = row.shape[0]
    for x in range(w):
        a, b, c = above[x], row[x], below[x]
        s[0, 1 + x] = min(a, b, c)
        s[1, 1 + x] = _med3(a, b, c)
        s[2, 1 + x] = max(a, b, c)
    for k in range(3):
        s[k, 0] = s[k, 1]
        s[k, w + 1] = s[k, w]


@nb.njit(**KERNEL)
def _median3(disp: np.ndarray, out: np.ndarray) -> None:
    """3 x 3: each column's three values sorted, then the median of (the largest low, the middle
    middle, the smallest high) of three neighbouring columns, which is the median of the nine; the
    rows above and below clamped to the image (the edge replicated)."""
    h, w = out.shape
    s = np.empty((3, w + 2), np.int16)
    for y in range(h):
        _sort_columns(disp[max(y - 1, 0)], disp[y], disp[min(y + 1, h - 1)], s)
        o = out[y]
        for x in range(w):
            o[x] = _med3(max(s[0, x], s[0, x + 1], s[0, x + 2]), _med3(s[1, x], s[1, x + 1], s[1, x + 2]),
                         min(s[2, x], s[2, x + 1], s[2, x + 2]))


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
    if size == 3:
        _median3(disp, out)
    else:
        _median(np.pad(disp, size // 2, mode="edge"), size, out)
