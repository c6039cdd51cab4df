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
    return (alpha * cur + (ALPHA_ONE - alpha) * prev + ALPHA_ONE // 2) // ALPHA_ONE


@nb.njit(**KERNEL)
def spatial_filter(disp: np.ndarray, alpha: int, delta: int, iterations: int, invalid: int) -> None:
    """In place; invalid pixels stay invalid and break the sweep."""
    h, w = disp.shape
    for _ in range(iterations):
        for y in range(h):
            for x in range(1, w):
                cur, prev = np.int32(disp[y, x]), np.int32(disp[y, x - 1])
                if cur != invalid and prev != invalid and abs(cur - prev) <= delta:
                    disp[y, x] = _blend(cur, prev, alpha)
            for x in range(w - 2, -1, -1):
                cur, prev = np.int32(disp[y, x]), np.int32(disp[y, x + 1])
                if cur != invalid and prev != invalid and abs(cur - prev) <= delta:
                    disp[y, x] = _blend(cur, prev, alpha)
        for y in range(1, h):
            for x in range(w):
                cur, prev = np.int32(disp[y, x]), np.int32(disp[y - 1, x])
                if cur != invalid and prev != invalid and abs(cur - prev) <= delta:
                    disp[y, x] = _blend(cur, prev, alpha)
        for y in range(h - 2, -1, -1):
            for x in range(w):
                cur, prev = np.int32(disp[y, x]), np.int32(disp[y + 1, x])
                if cur != invalid and prev != invalid and abs(cur - prev) <= delta:
                    disp[y, x] = _blend(cur, prev, alpha)
