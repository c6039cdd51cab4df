"""Speckle filter with cv::filterSpeckles semantics (4-connected regions, in place)."""
from __future__ import annotations

import numba as nb
import numpy as np

_JIT = dict(nogil=True, cache=True, boundscheck=False)


@nb.njit(**_JIT)
def filter_speckles(img: np.ndarray, new_val: int, max_size: int, max_diff: int,
                    labels: np.ndarray, stack: np.ndarray, rtype: np.ndarray) -> None:
    """Set every 4-connected region of at most ``max_size`` pixels to ``new_val``.

    Neighbours join a region when neither is ``new_val`` and they differ by at most
    ``max_diff``. Scratch: labels int32 (h, w), stack int32 (h*w, 2), rtype uint8 (h*w + 1).
    """
    h, w = img.shape
    labels[:, :] = 0
    cur = 0
    for i in range(h):
        for j in range(w):
            if img[i, j] == new_val:
                continue
            lab = labels[i, j]
            if lab != 0:
                if rtype[lab] != 0:
                    img[i, j] = new_val
                continue
            cur += 1
            labels[i, j] = cur
            count = 0
            top = 0
            stack[0, 0] = i
            stack[0, 1] = j
            top = 1
            while top > 0:
                top -= 1
                py = stack[top, 0]
                px = stack[top, 1]
                count += 1
                dp = np.int32(img[py, px])
                if py < h - 1 and labels[py + 1, px] == 0:
                    q = np.int32(img[py + 1, px])
                    if q != new_val and abs(dp - q) <= max_diff:
                        labels[py + 1, px] = cur
                        stack[top, 0] = py + 1
                        stack[top, 1] = px
                        top += 1
                if py > 0 and labels[py - 1, px] == 0:
                    q = np.int32(img[py - 1, px])
                    if q != new_val and abs(dp - q) <= max_diff:
                        labels[py - 1, px] = cur
                        stack[top, 0] = py - 1
                        stack[top, 1] = px
                        top += 1
                if px < w - 1 and labels[py, px + 1] == 0:
                    q = np.int32(img[py, px + 1])
                    if q != new_val and abs(dp - q) <= max_diff:
                        labels[py, px + 1] = cur
                        stack[top, 0] = py
                        stack[top, 1] = px + 1
                        top += 1
                if px > 0 and labels[py, px - 1] == 0:
                    q = np.int32(img[py, px - 1])
                    if q != new_val and abs(dp - q) <= max_diff:
                        labels[py, px - 1] = cur
                        stack[top, 0] = py
                        stack[top, 1] = px - 1
                        top += 1
            if count <= max_size:
                rtype[cur] = 1
                img[i, j] = new_val
            else:
                rtype[cur] = 0
