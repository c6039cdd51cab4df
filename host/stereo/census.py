"""Census transform of a stereo pair (numba, parallel over row stripes).

Bit per window neighbour (centre excluded): neighbour darker than the centre; the image is
extended by edge replication. Comparisons are made 64 pixels at a time into bytes (8
neighbours per byte) kept in registers, then shuffled into the uint64 codes
(sgm_simd.census_codes). The right image's
codes are stored mirrored along each row, so that the right pixels X - d of a left pixel X are
contiguous and ascending in d.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .sgm_simd import census_codes

_JIT = dict(nogil=True, cache=True, boundscheck=False, error_model="numpy")


@nb.njit(**_JIT)
def _pad_rows(img: np.ndarray, y0: int, y1: int, rx: int, ry: int, out: np.ndarray,
              o: int) -> None:
    """Rows y0 .. y1-1 of the edge-replicated image into out from row y0 - o: out[ry + y - o,
    rx + x] = img[y, x], with ry rows above and below and rx columns left and right (plus
    slack, left as is)."""
    h, w = img.shape
    for yy in range(y0, y1):
        src = img[min(max(yy - ry, 0), h - 1)]
        row = out[yy - o]
        for x in range(rx):
            row[x] = src[0]
            row[rx + w + x] = src[w - 1]
        for x in range(w):
            row[rx + x] = src[x]


def census_offsets(cw: int, ch: int, stride: int) -> np.ndarray:
    """census_codes' table for a cw x ch window over rows of ``stride`` bytes: the centre's
    offset, then the neighbours' in window order (row by row, the centre skipped)."""
    rx, ry = cw // 2, ch // 2
    nbrs = [i * stride + j for i in range(ch) for j in range(cw) if (i, j) != (ry, rx)]
    return np.array([ry * stride + rx, *nbrs], np.int64)


@nb.njit(**_JIT)
def _census_row(pad: np.ndarray, y: int, offs: np.ndarray, out: np.ndarray, rev: bool) -> None:
    """Census codes of row y of the padded image into out (its length, a multiple of 64, of
    them; rev: mirrored, pixel x at out[len - 1 - x])."""
    census_codes(pad.ravel(), y * pad.shape[1], offs, offs.shape[0] - 1, out.shape[0], out, rev)


@nb.njit(parallel=True, **_JIT)
def census_pair(left: np.ndarray, right: np.ndarray, cw: int, ch: int, bounds: np.ndarray,
                padl: np.ndarray, padr: np.ndarray, offs: np.ndarray, cl: np.ndarray,
                crr: np.ndarray) -> None:
    """cl[y, x] = census of left; crr[y, W-1-x] = census of right (mirrored rows), W =
    cl.shape[1]: the width rounded up to 64 (codes past the image are made too).

    padl, padr: (h + ch - 1, w + cw - 1 + 64) uint8; offs: census_offsets over their rows;
    bounds: row stripes of the padded height."""
    h, w = left.shape
    rx, ry = cw // 2, ch // 2
    for s in nb.prange(bounds.shape[0] - 1):
        _pad_rows(left, bounds[s], bounds[s + 1], rx, ry, padl, 0)
        _pad_rows(right, bounds[s], bounds[s + 1], rx, ry, padr, 0)
    nstripes = bounds.shape[0] - 1
    for s in nb.prange(nstripes):
        y0, y1 = h * s // nstripes, h * (s + 1) // nstripes
        for y in range(y0, y1):
            _census_row(padl, y, offs, cl[y], False)
            _census_row(padr, y, offs, crr[y, :cl.shape[1]], True)


@nb.njit(**_JIT)
def census_row_pair(left: np.ndarray, right: np.ndarray, y: int, cw: int, ch: int,
                    win: np.ndarray, offs: np.ndarray, cl: np.ndarray, crr: np.ndarray) -> None:
    """Row y of census_pair's output (cl[y], crr[y]) alone, for a worker that makes each row's
    codes just before it uses them. Scratch: win (ch, w + cw - 1 + 64) uint8 (the row's
    window of the padded image); offs: census_offsets over win's rows."""
    rx, ry = cw // 2, ch // 2
    _pad_rows(left, y, y + ch, rx, ry, win, y)
    _census_row(win, 0, offs, cl[y], False)
    _pad_rows(right, y, y + ch, rx, ry, win, y)
    _census_row(win, 0, offs, crr[y, :cl.shape[1]], True)
