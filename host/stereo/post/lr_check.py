"""Left-right check for any engine: the right view's disparity comes from matching the mirrored
pair (both images flipped, left and right swapped), so no engine has to expose one."""
from __future__ import annotations

from collections.abc import Callable

import numba as nb
import numpy as np
from stereocam.protocol.frame_messages import DISPARITY_SUBPIXEL

from ..jit import KERNEL


def right_view_disparity(match: Callable[[np.ndarray, np.ndarray], np.ndarray],
                         left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Disparity of the right view (right pixel x matches left pixel x + d) from ``match``, an
    engine's left-view matcher with the same disparity range, run on the mirrored pair."""
    mirrored = match(np.ascontiguousarray(right[:, ::-1]), np.ascontiguousarray(left[:, ::-1]))
    return np.ascontiguousarray(mirrored[:, ::-1])


@nb.njit(**KERNEL)
def lr_check(disp: np.ndarray, right_disp: np.ndarray, tolerance: int, invalid: int) -> None:
    """In place: invalidate left pixel x (disparity d) unless the right view's disparity at
    x - round(d) is valid and within ``tolerance`` px of d."""
    h, w = disp.shape
    tol = tolerance * DISPARITY_SUBPIXEL
    half = DISPARITY_SUBPIXEL // 2
    for y in range(h):
        for x in range(w):
            d = np.int32(disp[y, x])
            if d == invalid:
                continue
            xr = x - (d + half) // DISPARITY_SUBPIXEL
            if xr < 0 or xr >= w:
                disp[y, x] = invalid
                continue
            r = np.int32(right_disp[y, xr])
            if r == invalid or abs(r - d) > tol:
                disp[y, x] = invalid
