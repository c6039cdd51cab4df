"""Census transform of a stereo pair (numba, parallel over row stripes, or row by row).

Bit per window neighbour (centre excluded; sparse, the default: only the neighbours an odd
number of steps away, |dx| + |dy| odd, a chessboard's other colour): neighbour darker than the
centre; the image is extended by edge replication. With a margin t > 0 a bit is kept only where
the 3x3 binomial smoothing of the image differs between neighbour and centre by more than t: on flat,
noise-dominated areas the codes are then mostly zero in both eyes, so the matching cost is flat
there and the paths carry the disparity in from the edges instead of summing noise.
``noise_margin`` picks t from the image's own noise (median |3x3 Laplacian| //
MARGIN_DIVISOR): 0 on a clean image (plain census), 2-3 DN on the simulator's sensor.

Comparisons are made 64 pixels at a time into bytes (8 neighbours per byte) kept in registers,
then stored as they are, byte planes (cl[y, b], crr[y, b]: byte b of each code of row y;
census_simd.census_codes, census_codes_masked with a margin, which one chosen once per row;
census_simd.cost_run reads them). The right image's codes are stored mirrored along each row, so
that the right pixels X - d of a left pixel X are contiguous and ascending in d.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .jit import C_ARITHMETIC
from .sgm_params import MARGIN_DIVISOR, census_neighbours
from .census_simd import census_codes, census_codes_masked

_JIT = C_ARITHMETIC
LAPLACIAN_MAX = 16 * 255  # largest |3x3 Laplacian| of a uint8 image
LAPLACIAN_ROW_STEP = 4  # the noise estimate reads every 4th row


@nb.njit(**_JIT)
def laplacian_median(img: np.ndarray) -> int:
    """Lower median of |L| over the interior pixels of rows 1, 1 + LAPLACIAN_ROW_STEP, ...,
    L the 3x3 Laplacian [1 -2 1; -2 4 -2; 1 -2 1] (Immerkaer's noise operator: sigma ~ 0.247 *
    median); 0 without interior."""
    h, w = img.shape
    if h < 3 or w < 3:
        return 0
    n = ((h - 3) // LAPLACIAN_ROW_STEP + 1) * (w - 2)
    # |L| of a row first (a loop that vectorises), then counted into four histograms by
    # column: neighbours of a flat area share a bin, and one histogram would make each count
    # wait for the previous one's store
    hist = np.zeros((4, LAPLACIAN_MAX + 1), np.int32)
    row = np.empty(w - 2, np.int32)
    for y in range(1, h - 1, LAPLACIAN_ROW_STEP):
        a, b, c = img[y - 1], img[y], img[y + 1]
        for x in range(1, w - 1):
            r = (np.int32(a[x - 1]) - 2 * np.int32(a[x]) + np.int32(a[x + 1])
                 - 2 * np.int32(b[x - 1]) + 4 * np.int32(b[x]) - 2 * np.int32(b[x + 1])
                 + np.int32(c[x - 1]) - 2 * np.int32(c[x]) + np.int32(c[x + 1]))
            row[x - 1] = abs(r)
        for x in range(w - 2):
            hist[x & 3, row[x]] += 1
    seen = 0
    for v in range(LAPLACIAN_MAX + 1):
        seen += hist[0, v] + hist[1, v] + hist[2, v] + hist[3, v]
        if 2 * seen >= n:
            return v
    return LAPLACIAN_MAX


def noise_margin(img: np.ndarray) -> int:
    """The automatic census margin of ``img`` (SGMParams.census_margin < 0)."""
    return int(laplacian_median(img)) // MARGIN_DIVISOR


@nb.njit(**_JIT)
def _pad_rows(img: np.ndarray, y0: int, y1: int, rx: int, ry: int, out: np.ndarray,
              o: int) -> None:
    """Rows y0 .. y1-1 of the edge-replicated image XOR 0x80 (census_codes' input: uint8
    order as int8) into out from row y0 - o: out[ry + y - o, rx + x] = img[y, x] ^ 0x80, with
    ry rows above and below and rx columns left and right (plus slack, left as is)."""
    h, w = img.shape
    for yy in range(y0, y1):
        src = img[min(max(yy - ry, 0), h - 1)]
        row = out[yy - o]
        for x in range(rx):
            row[x] = src[0] ^ 0x80
            row[rx + w + x] = src[w - 1] ^ 0x80
        for x in range(w):
            row[rx + x] = src[x] ^ 0x80


@nb.njit(**_JIT)
def _smooth_px(a: np.ndarray, b: np.ndarray, c: np.ndarray, xl: int, x: int, xr: int) -> int:
    """3x3 binomial smoothing ((sum + 8) >> 4) at column x of rows a, b, c (neighbour
    columns xl, xr)."""
    s = (np.int32(a[xl]) + 2 * np.int32(b[xl]) + np.int32(c[xl])
         + 2 * (np.int32(a[x]) + 2 * np.int32(b[x]) + np.int32(c[x]))
         + np.int32(a[xr]) + 2 * np.int32(b[xr]) + np.int32(c[xr]))
    return (s + 8) >> 4


@nb.njit(**_JIT)
def _smooth_pad_row(img: np.ndarray, yy: int, rx: int, ry: int, row: np.ndarray) -> None:
    """Padded row yy (as _pad_rows, XOR 0x80) of the image's 3x3 binomial smoothing, edges
    replicated, into row."""
    h, w = img.shape
    y = min(max(yy - ry, 0), h - 1)
    a, b, c = img[max(y - 1, 0)], img[y], img[min(y + 1, h - 1)]
    for x in range(1, w - 1):
        row[rx + x] = np.uint8(((np.int32(a[x - 1]) + 2 * np.int32(a[x]) + np.int32(a[x + 1])
                                 + 2 * (np.int32(b[x - 1]) + 2 * np.int32(b[x]) + np.int32(b[x + 1]))
                                 + np.int32(c[x - 1]) + 2 * np.int32(c[x]) + np.int32(c[x + 1])
                                 + 8) >> 4) ^ 0x80)
    row[rx] = _smooth_px(a, b, c, 0, 0, min(1, w - 1)) ^ 0x80
    row[rx + w - 1] = _smooth_px(a, b, c, max(w - 2, 0), w - 1, w - 1) ^ 0x80
    for x in range(rx):
        row[x] = row[rx]
        row[rx + w + x] = row[rx + w - 1]


@nb.njit(**_JIT)
def _census_row(pad: np.ndarray, y: int, offs: np.ndarray, w: int, out: np.ndarray,
                rev: bool, spad: np.ndarray, sy: int, t: int) -> None:
    """The w (a multiple of 64) census codes of row y of the padded image into out (codes,
    or byte planes: census_codes; rev: mirrored, pixel x at w - 1 - x); margin t > 0: row
    sy of spad, the padded smoothed image, is the window's top row."""
    if t > 0:
        census_codes_masked(pad.ravel(), y * pad.shape[1], offs, offs.shape[0] - 1, w, out,
                            rev, spad.ravel(), sy * spad.shape[1], t)
    else:
        census_codes(pad.ravel(), y * pad.shape[1], offs, offs.shape[0] - 1, w, out, rev)


@nb.njit(parallel=True, **_JIT)
def census_pair(left: np.ndarray, right: np.ndarray, cw: int, ch: int, tl: int, tr: int,
                bounds: np.ndarray, padl: np.ndarray, padr: np.ndarray, spadl: np.ndarray,
                spadr: np.ndarray, offs: np.ndarray, cl: np.ndarray, crr: np.ndarray) -> None:
    """cl[y, b, x] = byte b of the census of left with margin tl; crr[y, b, W-1-x] = that of
    right with margin tr (byte planes; mirrored rows), W = cl.shape[2]: the width rounded up to
    64 (codes past the image are made too).

    padl, padr, spadl, spadr (the smoothed images, read with a margin only): (h + ch - 1, w +
    cw - 1 + 64) uint8; offs: census_offsets over their rows; bounds: row stripes of the
    padded height."""
    h, w = left.shape
    rx, ry = cw // 2, ch // 2
    for s in nb.prange(bounds.shape[0] - 1):
        _pad_rows(left, bounds[s], bounds[s + 1], rx, ry, padl, 0)
        _pad_rows(right, bounds[s], bounds[s + 1], rx, ry, padr, 0)
        for yy in range(bounds[s], bounds[s + 1]):
            if tl > 0:
                _smooth_pad_row(left, yy, rx, ry, spadl[yy])
            if tr > 0:
                _smooth_pad_row(right, yy, rx, ry, spadr[yy])
    nstripes = bounds.shape[0] - 1
    for s in nb.prange(nstripes):
        y0, y1 = h * s // nstripes, h * (s + 1) // nstripes
        for y in range(y0, y1):
            _census_row(padl, y, offs, cl.shape[2], cl[y], False, spadl, y, tl)
            _census_row(padr, y, offs, cl.shape[2], crr[y], True, spadr, y, tr)


def census_offsets(cw: int, ch: int, sparse: bool, stride: int) -> np.ndarray:
    """census_codes' table for a cw x ch window over rows of ``stride`` bytes: the centre's
    offset, then the neighbours' (census_neighbours: row by row, the centre skipped; sparse:
    only those an odd number of steps away)."""
    rx, ry = cw // 2, ch // 2
    nbrs = [(ry + dy) * stride + rx + dx for dy, dx in census_neighbours(cw, ch, sparse)]
    return np.array([ry * stride + rx, *nbrs], np.int64)


@nb.njit(**_JIT)
def census_row_pair(left: np.ndarray, right: np.ndarray, y: int, cw: int, ch: int, tl: int,
                    tr: int, win: tuple, offs: np.ndarray, cl: np.ndarray,
                    crr: np.ndarray) -> None:
    """Row y of census_pair's output (cl[y], crr[y]) alone, for a worker that makes each row's
    codes just before it uses them. Scratch win = (raw, smooth, key): raw (ch, w + cw - 1 +
    64) uint8, the row's window of the padded image; with a margin smooth (2, 2 * ch, that
    width) uint8, the padded smoothed left and right rows, padded row r in slots r % ch and
    r % ch + ch (so that any ch consecutive rows are contiguous), key (ch,) int64 the padded
    row each slot holds (-1: none; reset per frame), so a worker stepping row by row smooths
    one new row per row; offs: census_offsets over those rows."""
    raw, smooth, key = win
    rx, ry = cw // 2, ch // 2
    if tl > 0 or tr > 0:
        for yy in range(y, y + ch):
            slot = yy % ch
            if key[slot] != yy:
                if tl > 0:
                    _smooth_pad_row(left, yy, rx, ry, smooth[0, slot])
                    smooth[0, slot + ch] = smooth[0, slot]
                if tr > 0:
                    _smooth_pad_row(right, yy, rx, ry, smooth[1, slot])
                    smooth[1, slot + ch] = smooth[1, slot]
                key[slot] = yy
    _pad_rows(left, y, y + ch, rx, ry, raw, y)
    _census_row(raw, 0, offs, cl.shape[2], cl[y], False, smooth[0], y % ch, tl)
    _pad_rows(right, y, y + ch, rx, ry, raw, y)
    _census_row(raw, 0, offs, cl.shape[2], crr[y], True, smooth[1], y % ch, tr)
