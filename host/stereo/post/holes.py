"""Hole filling: invalid pixels take a disparity from valid neighbours.

nearest: the nearest valid pixel of the row (left or right; a tie takes the smaller disparity).
background: Hirschmueller's interpolation (SGM paper, 2008) — the first valid disparity along each
of 8 paths, the second smallest of those found (the background, robust to one stray value), the
only one when just one path finds one; pixels no path reaches stay invalid. Branch-free selects
throughout: on a map of small holes every pixel's branch would be a coin toss.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from ..jit import KERNEL


@nb.njit(**KERNEL)
def fill_nearest(disp: np.ndarray, invalid: int) -> None:
    """In place: every invalid pixel takes the nearest valid disparity of its row."""
    h, w = disp.shape
    left = np.empty(w, np.int32)  # column of the nearest valid pixel at or left of x (-1: none)
    for y in range(h):
        last = -1
        for x in range(w):
            if disp[y, x] != invalid:
                last = x
            left[x] = last
        nxt = -1  # column of the nearest valid pixel at or right of x
        for x in range(w - 1, -1, -1):
            if disp[y, x] != invalid:
                nxt = x
                continue
            lx = left[x]
            if lx < 0 and nxt < 0:
                continue
            if nxt < 0 or (lx >= 0 and x - lx < nxt - x):
                disp[y, x] = disp[y, lx]
            elif lx < 0 or nxt - x < x - lx:
                disp[y, x] = disp[y, nxt]
            else:
                disp[y, x] = min(disp[y, lx], disp[y, nxt])


NONE = 32767  # no disparity found along a path: above every disparity * 16 of the protocol's
# range (min_disparity + num_disparities <= 512 px, 8192)


@nb.njit(**KERNEL)
def _low2(m1: np.int32, m2: np.int32, v: np.int32) -> tuple[np.int32, np.int32]:
    """The two smallest of m1 <= m2 and v."""
    return min(m1, v), min(m2, max(m1, v))


@nb.njit(**KERNEL)
def _paths_from(disp: np.ndarray, y: int, invalid: int, along_row: bool, prev: np.ndarray,
                cur: np.ndarray, left: np.ndarray, right: np.ndarray) -> None:
    """Row y's first valid disparity (the pixel's own, else its path's) along the paths from the
    row before: cur[d, 1 + x] from prev (d = 0, 1, 2: straight, from the left, from the right;
    NONE padded at both ends), and with along_row the row's own (left[x]: from the left, right[x]:
    from the right)."""
    w = disp.shape[1]
    row = disp[y]
    for x in range(w):
        v = np.int32(row[x])
        ok = v != invalid
        cur[0, 1 + x] = v if ok else prev[0, 1 + x]
        cur[1, 1 + x] = v if ok else prev[1, x]
        cur[2, 1 + x] = v if ok else prev[2, 2 + x]
    if along_row:
        seen = np.int32(NONE)
        for x in range(w):
            v = np.int32(row[x])
            seen = v if v != invalid else seen
            left[x] = seen
        seen = np.int32(NONE)
        for x in range(w - 1, -1, -1):
            v = np.int32(row[x])
            seen = v if v != invalid else seen
            right[x] = seen


@nb.njit(**KERNEL)
def fill_background(disp: np.ndarray, invalid: int, low: np.ndarray) -> None:
    """In place: Hirschmueller background interpolation. Scratch: low int16 (2, h, w).

    Two passes, no plane per path: top-down the paths from above and along the row, whose two
    smallest disparities each pixel keeps in low; then bottom-up the paths from below, and the
    second smallest of all (the only one when one path found one) fills each invalid pixel."""
    h, w = disp.shape
    bufs = np.full((2, 3, w + 2), NONE, np.int32)  # per pass: the previous and this row's paths
    left = np.empty(w, np.int32)
    right = np.empty(w, np.int32)
    for y in range(h):
        prev, cur = bufs[y & 1], bufs[1 - (y & 1)]
        _paths_from(disp, y, invalid, True, prev, cur, left, right)
        for x in range(w):
            m1, m2 = _low2(np.int32(NONE), np.int32(NONE), cur[0, 1 + x])
            m1, m2 = _low2(m1, m2, cur[1, 1 + x])
            m1, m2 = _low2(m1, m2, cur[2, 1 + x])
            m1, m2 = _low2(m1, m2, left[x])
            m1, m2 = _low2(m1, m2, right[x])
            low[0, y, x] = m1
            low[1, y, x] = m2
    bufs[:] = NONE
    for y in range(h - 1, -1, -1):
        prev, cur = bufs[y & 1], bufs[1 - (y & 1)]
        _paths_from(disp, y, invalid, False, prev, cur, left, right)
        row = disp[y]
        for x in range(w):
            m1, m2 = _low2(np.int32(low[0, y, x]), np.int32(low[1, y, x]), cur[0, 1 + x])
            m1, m2 = _low2(m1, m2, cur[1, 1 + x])
            m1, m2 = _low2(m1, m2, cur[2, 1 + x])
            v = np.int32(row[x])
            fill = m2 if m2 != NONE else m1 if m1 != NONE else v
            row[x] = fill if v == invalid else v
