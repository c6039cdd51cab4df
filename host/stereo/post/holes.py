"""Hole filling: invalid pixels take a disparity from valid neighbours.

nearest: the nearest valid pixel of the row (left or right; a tie takes the smaller disparity).
background: Hirschmueller's interpolation (SGM paper, 2008) — the first valid disparity along each
of 8 paths, the second smallest of those found (the background, robust to one stray value), the
only one when just one path finds one; pixels no path reaches stay invalid.
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


@nb.njit(**KERNEL)
def _seen(disp: np.ndarray, invalid: int, dy: int, dx: int, out: np.ndarray) -> None:
    """out[y, x]: the first valid disparity from (y, x) stepping (dy, dx) (invalid: none)."""
    h, w = disp.shape
    ys = range(h - 1, -1, -1) if dy > 0 else range(h)
    for y in ys:
        py = y + dy
        row_in = 0 <= py < h
        xs = range(w - 1, -1, -1) if dx > 0 else range(w)
        for x in xs:
            v = disp[y, x]
            if v == invalid:
                px = x + dx
                if row_in and 0 <= px < w:
                    v = out[py, px]
            out[y, x] = v


@nb.njit(**KERNEL)
def fill_background(disp: np.ndarray, invalid: int, seen: np.ndarray) -> None:
    """In place: Hirschmueller background interpolation. Scratch: seen int16 (8, h, w)."""
    h, w = disp.shape
    dys = (0, 0, 1, -1, 1, 1, -1, -1)
    dxs = (1, -1, 0, 0, 1, -1, 1, -1)
    for k in range(8):
        _seen(disp, invalid, dys[k], dxs[k], seen[k])
    vals = np.empty(8, np.int32)
    for y in range(h):
        for x in range(w):
            if disp[y, x] != invalid:
                continue
            n = 0
            for k in range(8):
                v = np.int32(seen[k, y, x])
                if v != invalid:
                    j = n  # insertion sort: at most 8 values
                    while j > 0 and vals[j - 1] > v:
                        vals[j] = vals[j - 1]
                        j -= 1
                    vals[j] = v
                    n += 1
            if n > 0:
                disp[y, x] = vals[min(n, 2) - 1]
