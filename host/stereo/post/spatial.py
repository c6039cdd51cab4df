"""Edge-preserving spatial filter: the recursive domain transform as librealsense's spatial filter
runs it (Gastal & Oliveira 2011), in integers. Each iteration sweeps every row left to right and
back, then every column down and up; along a sweep a valid pixel whose filtered predecessor is valid
and within ``delta`` becomes (alpha * itself + (256 - alpha) * predecessor + 128) >> 8."""
from __future__ import annotations

import numba as nb
import numpy as np

from ..jit import KERNEL

ALPHA_ONE = 256  # spatial_alpha / temporal_alpha are in 1/256
STRIP = 16
"""Rows swept together: a strip is copied into a buffer with the rows along its second axis, so one
step of all 16 sweeps is one vector operation (a row's own steps wait on each other)."""


@nb.njit(inline="always")
def _step(cur: np.int32, prev: np.int32, alpha: np.int32, delta: np.int32, invalid: np.int32) -> np.int32:
    """cur after one step of a sweep from its filtered predecessor prev: the blend
    (alpha * cur + (256 - alpha) * prev + 128) >> 8 (the temporal filter's too) written as
    prev + (alpha * (cur - prev) + 128) >> 8 (equal: 256 * prev leaves the floor unchanged), every
    operation cast back to 32 bits (numba widens integer arithmetic to 64, which would take
    vectors of 4), and branch-free: a select."""
    d = np.int32(cur - prev)
    blend = np.int32(prev + np.int32(np.int32(np.int32(alpha * d) + np.int32(ALPHA_ONE // 2)) >> np.int32(8)))
    ok = (cur != invalid) & (prev != invalid) & (np.int32(max(d, np.int32(-d))) <= delta)
    return blend if ok else cur


@nb.njit(**KERNEL)
def _sweep_lines(lines: np.ndarray, n: int, alpha: np.int32, delta: np.int32, invalid: np.int32) -> None:
    """Every column of ``lines[:n]`` (a line runs along axis 0) swept forward, then back: each step
    a whole row of the array at once (the loop over it vectorises)."""
    s = lines.shape[1]
    for x in range(1, n):
        p, c = lines[x - 1], lines[x]
        for i in range(s):
            c[i] = _step(np.int32(c[i]), np.int32(p[i]), alpha, delta, invalid)
    for x in range(n - 2, -1, -1):
        p, c = lines[x + 1], lines[x]
        for i in range(s):
            c[i] = _step(np.int32(c[i]), np.int32(p[i]), alpha, delta, invalid)


@nb.njit(**KERNEL)
def spatial_filter(disp: np.ndarray, alpha: int, delta: int, iterations: int, invalid: int) -> None:
    """In place; invalid pixels stay invalid and break the sweep. The row sweeps run on strips of
    ``STRIP`` rows copied into a buffer with the rows along its second axis (the last strip repeats
    the last row); the column sweeps run on the map itself."""
    h, w = disp.shape
    a, dl, inv = np.int32(alpha), np.int32(delta), np.int32(invalid)
    strip = np.empty((w, STRIP), np.int16)
    for _ in range(iterations):
        for y0 in range(0, h, STRIP):
            for i in range(STRIP):
                row = disp[min(y0 + i, h - 1)]
                for x in range(w):
                    strip[x, i] = row[x]
            _sweep_lines(strip, w, a, dl, inv)
            for i in range(min(STRIP, h - y0)):
                row = disp[y0 + i]
                for x in range(w):
                    row[x] = strip[x, i]
        _sweep_lines(disp, h, a, dl, inv)
