"""Decimation without a change of format: each n x n block (from the top left; partial blocks at the
right and bottom edges) takes the lower median of its valid pixels, written to the whole block, so
the frame keeps its size on the wire; a block without valid pixels stays invalid."""
from __future__ import annotations

import numba as nb
import numpy as np

from ..jit import KERNEL


@nb.njit(**KERNEL)
def decimate(disp: np.ndarray, n: int, invalid: int) -> None:
    """In place."""
    h, w = disp.shape
    vals = np.empty(n * n, np.int16)
    for by in range(0, h, n):
        for bx in range(0, w, n):
            k = 0
            for y in range(by, min(by + n, h)):
                for x in range(bx, min(bx + n, w)):
                    v = disp[y, x]
                    if v != invalid:
                        j = k
                        while j > 0 and vals[j - 1] > v:
                            vals[j] = vals[j - 1]
                            j -= 1
                        vals[j] = v
                        k += 1
            m = vals[(k - 1) // 2] if k > 0 else invalid
            for y in range(by, min(by + n, h)):
                for x in range(bx, min(bx + n, w)):
                    disp[y, x] = m
