"""Edge-preserving spatial filter: the recursive domain transform as librealsense's spatial filter
runs it (Gastal & Oliveira 2011), in integers. Each iteration sweeps every row left to right and
back, then every column down and up; along a sweep a valid pixel whose filtered predecessor is valid
and within ``delta`` becomes (alpha * itself + (256 - alpha) * predecessor + 128) >> 8."""
from __future__ import annotations

import numba as nb
import numpy as np

from ..jit import KERNEL

ALPHA_ONE = 256  # spatial_alpha / temporal_alpha are in 1/256


@nb.njit(**KERNEL)
def _blend(cur: np.int32, prev: np.int32, alpha: int) -> np.int32:
    """(alpha * cur + (256 - alpha) * prev + 128) // 256 (the temporal filter's blend too)."""
    return (alpha * cur + (ALPHA_ONE - alpha) * prev + ALPHA_ONE // 2) >> 8  # floor of / 256


@nb.njit(**KERNEL)
def _step(cur: np.int32, prev: np.int32, alpha: int, delta: int, invalid: np.int32) -> np.int32:
    """cur after one step of a sweep from its filtered predecessor prev (branch-free: a select)."""
    blend = _blend(cur, prev, alpha)
    ok = (cur != invalid) & (prev != invalid) & (abs(cur - prev) <= delta)
    return blend if ok else cur


@nb.njit(**KERNEL)
def spatial_filter(disp: np.ndarray, alpha: int, delta: int, iterations: int, invalid: int) -> None:
    """In place; invalid pixels stay invalid and break the sweep. Along a row each step waits on
    the one before, the predecessor kept in a register, two rows per loop; the column sweeps step
    a whole row at once (no dependency across it: the loop vectorises)."""
    h, w = disp.shape
    inv = np.int32(invalid)
    for _ in range(iterations):
        for y in range(0, h, 2):  # two rows per loop: two independent chains fill each other's waits
            a, b = disp[y], disp[min(y + 1, h - 1)]  # (the last row twice when h is odd: the
            pa, pb = np.int32(a[0]), np.int32(b[0])  # same values written twice)
            for x in range(1, w):
                pa = _step(np.int32(a[x]), pa, alpha, delta, inv)
                pb = _step(np.int32(b[x]), pb, alpha, delta, inv)
                a[x] = pa
                b[x] = pb
            pa, pb = np.int32(a[w - 1]), np.int32(b[w - 1])
            for x in range(w - 2, -1, -1):
                pa = _step(np.int32(a[x]), pa, alpha, delta, inv)
                pb = _step(np.int32(b[x]), pb, alpha, delta, inv)
                a[x] = pa
                b[x] = pb
        for y in range(1, h):
            above, row = disp[y - 1], disp[y]
            for x in range(w):
                row[x] = _step(np.int32(row[x]), np.int32(above[x]), alpha, delta, inv)
        for y in range(h - 2, -1, -1):
            below, row = disp[y + 1], disp[y]
            for x in range(w):
                row[x] = _step(np.int32(row[x]), np.int32(below[x]), alpha, delta, inv)
