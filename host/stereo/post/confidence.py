"""The confidence plane (SPEC §5.3): how well the matched disparity of each pixel is supported by its
neighbours, from the map after the left-right check and before any filling or filtering."""
from __future__ import annotations

import numba as nb
import numpy as np

from stereocam.protocol.frame_messages import (CONFIDENCE_BASE, CONFIDENCE_FILLED, CONFIDENCE_PER_NEIGHBOUR,
                                               DISPARITY_SUBPIXEL)

from ..jit import KERNEL


@nb.njit(**KERNEL)
def confidence(matched: np.ndarray, final: np.ndarray, invalid: int, out: np.ndarray) -> None:
    """out (uint8): 0 where ``final`` is invalid, CONFIDENCE_FILLED where ``matched`` is (a filled hole),
    else CONFIDENCE_BASE + CONFIDENCE_PER_NEIGHBOUR * (8-neighbours of ``matched`` within 1 px)."""
    h, w = matched.shape
    for y in range(h):
        for x in range(w):
            if final[y, x] == invalid:
                out[y, x] = 0
                continue
            c = np.int32(matched[y, x])
            if c == invalid:
                out[y, x] = CONFIDENCE_FILLED
                continue
            n = 0
            for dy in range(-1, 2):
                for dx in range(-1, 2):
                    yy, xx = y + dy, x + dx
                    if (dy or dx) and 0 <= yy < h and 0 <= xx < w:
                        v = np.int32(matched[yy, xx])
                        if v != invalid and abs(v - c) <= DISPARITY_SUBPIXEL:
                            n += 1
            out[y, x] = CONFIDENCE_BASE + CONFIDENCE_PER_NEIGHBOUR * n
