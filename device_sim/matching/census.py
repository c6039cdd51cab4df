"""Census transform of a stereo pair (numba, parallel over row stripes).

Bit per window neighbour (centre excluded): neighbour darker than the centre; the image is
extended by edge replication. The right image's codes are stored mirrored along each row, so
that the right pixels X - d of a left pixel X are contiguous and ascending in d.
"""
from __future__ import annotations

import numba as nb
import numpy as np

_JIT = dict(nogil=True, cache=True, boundscheck=False, error_model="numpy")


@nb.njit(**_JIT)
def _pad_row(img: np.ndarray, y: int, rx: int, out: np.ndarray) -> None:
    """Row y of img with rx replicated pixels on each side."""
    w = img.shape[1]
    for x in range(rx):
        out[x] = img[y, 0]
        out[rx + w + x] = img[y, w - 1]
    for x in range(w):
        out[rx + x] = img[y, x]


@nb.njit(**_JIT)
def _census_row(img: np.ndarray, y: int, cw: int, ch: int, rows: np.ndarray,
                code: np.ndarray) -> None:
    """Census codes of row y into code[0:w]; rows is (ch, w + cw - 1) scratch."""
    h, w = img.shape
    rx, ry = cw // 2, ch // 2
    for i in range(ch):
        _pad_row(img, min(max(y - ry + i, 0), h - 1), rx, rows[i])
    centre = rows[ry]
    for x in range(w):
        code[x] = 0
    bit = np.uint64(0)
    for i in range(ch):
        row = rows[i]
        for j in range(cw):
            if i == ry and j == rx:
                continue
            for x in range(w):
                code[x] |= np.uint64(row[x + j] < centre[x + rx]) << bit
            bit += np.uint64(1)


@nb.njit(parallel=True, **_JIT)
def census_pair(left: np.ndarray, right: np.ndarray, cw: int, ch: int, bounds: np.ndarray,
                rows: np.ndarray, code: np.ndarray, cl: np.ndarray, crr: np.ndarray) -> None:
    """cl[y, x] = census of left; crr[y, w-1-x] = census of right (mirrored rows).

    Scratch has one slice per thread: rows (n, ch, w + cw - 1) uint8, code (n, w) uint64."""
    w = left.shape[1]
    for s in nb.prange(bounds.shape[0] - 1):
        t = nb.get_thread_id()
        for y in range(bounds[s], bounds[s + 1]):
            _census_row(left, y, cw, ch, rows[t], cl[y])
            _census_row(right, y, cw, ch, rows[t], code[t])
            c, out = code[t], crr[y]
            for x in range(w):
                out[w - 1 - x] = c[x]
