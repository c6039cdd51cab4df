"""Census transform of a stereo pair (numba, parallel over row stripes).

Bit per window neighbour (centre excluded): neighbour darker than the centre; the image is
extended by edge replication. Comparisons are made 64 pixels at a time into bytes (8
neighbours per byte), which are then shifted into place in the uint64 codes. The right image's
codes are stored mirrored along each row, so that the right pixels X - d of a left pixel X are
contiguous and ascending in d.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .sgm_simd import census_bits

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


@nb.njit(**_JIT)
def _flush(byte: np.ndarray, group: int, w: int, code: np.ndarray) -> None:
    s = np.uint64(8 * group)
    for x in range(w):
        code[x] |= np.uint64(byte[x]) << s


@nb.njit(**_JIT)
def _census_row(pad: np.ndarray, y: int, cw: int, ch: int, w: int, byte: np.ndarray,
                code: np.ndarray) -> None:
    """Census codes of row y into code[0:w] from the padded image."""
    rx, ry = cw // 2, ch // 2
    centre = pad[y + ry]
    code[:w] = 0
    n = 0  # comparisons so far; bit n of the code
    for q in range(cw * ch):
        i, j = q // cw, q % cw
        if i == ry and j == rx:
            continue
        if n & 7 == 0:
            byte[:] = 0
        census_bits(byte, pad[y + i], j, centre, rx, np.uint8(1 << (n & 7)), w)
        n += 1
        if n & 7 == 0:
            _flush(byte, (n - 1) >> 3, w, code)
    if n & 7 != 0:
        _flush(byte, (n - 1) >> 3, w, code)


@nb.njit(parallel=True, **_JIT)
def census_pair(left: np.ndarray, right: np.ndarray, cw: int, ch: int, bounds: np.ndarray,
                padl: np.ndarray, padr: np.ndarray, byte: np.ndarray, code: np.ndarray,
                cl: np.ndarray, crr: np.ndarray) -> None:
    """cl[y, x] = census of left; crr[y, w-1-x] = census of right (mirrored rows).

    padl, padr: (h + ch - 1, w + cw - 1 + 64) uint8; per-thread scratch byte (n, w + 64)
    uint8 and code (n, w) uint64; bounds: row stripes of the padded height."""
    h, w = left.shape
    rx, ry = cw // 2, ch // 2
    for s in nb.prange(bounds.shape[0] - 1):
        _pad_rows(left, bounds[s], bounds[s + 1], rx, ry, padl, 0)
        _pad_rows(right, bounds[s], bounds[s + 1], rx, ry, padr, 0)
    nstripes = bounds.shape[0] - 1
    for s in nb.prange(nstripes):
        t = nb.get_thread_id()
        y0, y1 = h * s // nstripes, h * (s + 1) // nstripes
        for y in range(y0, y1):
            _census_row(padl, y, cw, ch, w, byte[t], cl[y])
            _census_row(padr, y, cw, ch, w, byte[t], code[t])
            c, out = code[t], crr[y]
            for x in range(w):
                out[w - 1 - x] = c[x]


@nb.njit(**_JIT)
def census_row_pair(left: np.ndarray, right: np.ndarray, y: int, cw: int, ch: int,
                    win: np.ndarray, byte: np.ndarray, code: np.ndarray, cl: np.ndarray,
                    crr: np.ndarray) -> None:
    """Row y of census_pair's output (cl[y], crr[y]) alone, for a worker that makes each row's
    codes just before it uses them. Scratch: win (ch, w + cw - 1 + 64) uint8 (the row's
    window of the padded image), byte (w + 64) uint8, code (w) uint64."""
    w = left.shape[1]
    rx, ry = cw // 2, ch // 2
    _pad_rows(left, y, y + ch, rx, ry, win, y)
    _census_row(win, 0, cw, ch, w, byte, cl[y])
    _pad_rows(right, y, y + ch, rx, ry, win, y)
    _census_row(win, 0, cw, ch, w, byte, code)
    out = crr[y]
    for x in range(w):
        out[w - 1 - x] = code[x]
