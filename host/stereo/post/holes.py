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
def _path(row: np.ndarray, invalid: np.int16, prev: np.ndarray, cur: np.ndarray, off: int) -> None:
    """cur[1 + x]: row[x] where valid, else prev[off + x] (off 1: the path straight down, 0: from
    the left, 2: from the right). Both values loaded, then selected: a load under a branch would
    not vectorise."""
    for x in range(row.shape[0]):
        v = row[x]
        p = prev[off + x]
        cur[1 + x] = v if v != invalid else p


@nb.njit(**KERNEL)
def _paths_from(row: np.ndarray, invalid: np.int16, prev: np.ndarray, cur: np.ndarray, along_row: bool) -> None:
    """Row ``row``'s first valid disparity (the pixel's own, else its path's) along the paths from the
    row before: cur[d, 1 + x] from prev (d = 0, 1, 2: straight, from the left, from the right; NONE
    padded at both ends), and with along_row the row's own in cur[3] (from the left) and cur[4]
    (from the right)."""
    _path(row, invalid, prev[0], cur[0], 1)
    _path(row, invalid, prev[1], cur[1], 0)
    _path(row, invalid, prev[2], cur[2], 2)
    if along_row:
        w = row.shape[0]
        seen = np.int16(NONE)
        for x in range(w):
            v = row[x]
            seen = v if v != invalid else seen
            cur[3, 1 + x] = seen
        seen = np.int16(NONE)
        for x in range(w - 1, -1, -1):
            v = row[x]
            seen = v if v != invalid else seen
            cur[4, 1 + x] = seen


@nb.njit(**KERNEL)
def _low_from_above(cur: np.ndarray, low: np.ndarray, y: int) -> None:
    """low[:, y]: the two smallest of the five paths' values in cur (m1 <= m2)."""
    for x in range(low.shape[2]):
        a, b = cur[0, 1 + x], cur[1, 1 + x]
        m1, m2 = min(a, b), max(a, b)
        for k in range(2, 5):
            v = cur[k, 1 + x]
            m1, m2 = min(m1, v), min(m2, max(m1, v))
        low[0, y, x] = m1
        low[1, y, x] = m2


@nb.njit(**KERNEL)
def _fill_row(cur: np.ndarray, low: np.ndarray, y: int, row: np.ndarray, invalid: np.int16) -> None:
    """Each invalid pixel of row y takes the second smallest of all eight paths' values (low[:, y]
    and the three from below in cur), the only one when one path found one."""
    none = np.int16(NONE)
    for x in range(row.shape[0]):
        m1, m2 = low[0, y, x], low[1, y, x]
        for k in range(3):
            v = cur[k, 1 + x]
            m1, m2 = min(m1, v), min(m2, max(m1, v))
        d = row[x]
        fill = m2 if m2 != none else m1 if m1 != none else d
        row[x] = fill if d == invalid else d


@nb.njit(**KERNEL)
def fill_background(disp: np.ndarray, invalid: int, low: np.ndarray) -> None:
    """In place: Hirschmueller background interpolation. Scratch: low int16 (2, h, w).

    Two passes, no plane per path: top-down the paths from above and along the row, whose two
    smallest disparities each pixel keeps in low; then bottom-up the paths from below, and the
    second smallest of all (the only one when one path found one) fills each invalid pixel. The
    paths' values are int16 rows of one array per pass direction (each loop touches two or three
    arrays, few enough for the vectoriser's overlap checks)."""
    h, w = disp.shape
    inv = np.int16(invalid)
    bufs = np.full((2, 5, w + 2), np.int16(NONE), np.int16)  # the previous and this row's paths
    for y in range(h):
        prev, cur = bufs[y & 1], bufs[1 - (y & 1)]
        _paths_from(disp[y], inv, prev, cur, True)
        _low_from_above(cur, low, y)
    bufs[:] = NONE
    for y in range(h - 1, -1, -1):
        prev, cur = bufs[y & 1], bufs[1 - (y & 1)]
        _paths_from(disp[y], inv, prev, cur, False)
        _fill_row(cur, low, y, disp[y], inv)
