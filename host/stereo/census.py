"""Census transform of a stereo pair (numba, parallel over row stripes).

Bit per window neighbour (centre excluded): neighbour darker than the centre; the image is
extended by edge replication. With a margin t > 0 a bit is kept only where the 3x3 binomial
smoothing of the image differs between neighbour and centre by more than t: on flat,
noise-dominated areas the codes are then mostly zero in both eyes, so the matching cost is flat
there and the paths carry the disparity in from the edges instead of summing noise.
``noise_margin`` picks t from the image's own noise (median |3x3 Laplacian| //
MARGIN_DIVISOR): 0 on a clean image (plain census), 2-3 DN on the simulator's sensor.

Comparisons are made 64 pixels at a time into bytes (8 neighbours per byte), which are then
shifted into place in the uint64 codes. The right image's codes are stored mirrored along each
row, so that the right pixels X - d of a left pixel X are contiguous and ascending in d.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .sgm_params import MARGIN_DIVISOR
from .census_simd import census_bits_masked
from .sgm_simd import census_bits

_JIT = dict(nogil=True, cache=True, boundscheck=False, error_model="numpy")
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
    hist = np.zeros(LAPLACIAN_MAX + 1, np.int64)
    for y in range(1, h - 1, LAPLACIAN_ROW_STEP):
        a, b, c = img[y - 1], img[y], img[y + 1]
        for x in range(1, w - 1):
            r = (np.int32(a[x - 1]) - 2 * np.int32(a[x]) + np.int32(a[x + 1])
                 - 2 * np.int32(b[x - 1]) + 4 * np.int32(b[x]) - 2 * np.int32(b[x + 1])
                 + np.int32(c[x - 1]) - 2 * np.int32(c[x]) + np.int32(c[x + 1]))
            hist[abs(r)] += 1
    seen = 0
    for v in range(LAPLACIAN_MAX + 1):
        seen += hist[v]
        if 2 * seen >= n:
            return v
    return LAPLACIAN_MAX


def noise_margin(img: np.ndarray) -> int:
    """The automatic census margin of ``img`` (SGMParams.census_margin < 0)."""
    return int(laplacian_median(img)) // MARGIN_DIVISOR


@nb.njit(**_JIT)
def _smooth_rows(img: np.ndarray, y0: int, y1: int, out: np.ndarray) -> None:
    """Rows y0 .. y1-1 of the 3x3 binomial smoothing ((sum + 8) >> 4), edges replicated."""
    h, w = img.shape
    v = np.empty(w + 2, np.int16)  # the column sums, one replicated each side
    for y in range(y0, y1):
        a, b, c = img[max(y - 1, 0)], img[y], img[min(y + 1, h - 1)]
        for x in range(w):
            v[x + 1] = np.int16(a[x]) + 2 * np.int16(b[x]) + np.int16(c[x])
        v[0], v[w + 1] = v[1], v[w]
        row = out[y]
        for x in range(w):
            row[x] = np.uint8((v[x] + 2 * v[x + 1] + v[x + 2] + 8) >> 4)


@nb.njit(**_JIT)
def _pad_rows(img: np.ndarray, y0: int, y1: int, rx: int, ry: int, out: np.ndarray) -> None:
    """Rows y0 .. y1-1 of the edge-replicated image: out[ry + y, rx + x] = img[y, x], with
    ry rows above and below and rx columns left and right (plus slack, left as is)."""
    h, w = img.shape
    for yy in range(y0, y1):
        src = img[min(max(yy - ry, 0), h - 1)]
        row = out[yy]
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
def _census_row(pad: np.ndarray, spad: np.ndarray, y: int, cw: int, ch: int, w: int, t: int,
                byte: np.ndarray, code: np.ndarray) -> None:
    """Census codes of row y into code[0:w] from the padded image (and, margin t > 0, the
    padded smoothed image spad: a bit needs |spad neighbour - spad centre| > t)."""
    rx, ry = cw // 2, ch // 2
    centre, scentre = pad[y + ry], spad[y + ry]
    code[:w] = 0
    n = 0  # comparisons so far; bit n of the code
    for q in range(cw * ch):
        i, j = q // cw, q % cw
        if i == ry and j == rx:
            continue
        if n & 7 == 0:
            byte[:] = 0
        bit = np.uint8(1 << (n & 7))
        if t > 0:
            census_bits_masked(byte, pad[y + i], centre, spad[y + i], scentre, j, rx, t, bit, w)
        else:
            census_bits(byte, pad[y + i], j, centre, rx, bit, w)
        n += 1
        if n & 7 == 0:
            _flush(byte, (n - 1) >> 3, w, code)
    if n & 7 != 0:
        _flush(byte, (n - 1) >> 3, w, code)


@nb.njit(parallel=True, **_JIT)
def census_pair(left: np.ndarray, right: np.ndarray, cw: int, ch: int, tl: int, tr: int,
                bounds: np.ndarray, padl: np.ndarray, padr: np.ndarray, smooth: np.ndarray,
                spadl: np.ndarray, spadr: np.ndarray, byte: np.ndarray, code: np.ndarray,
                cl: np.ndarray, crr: np.ndarray) -> None:
    """cl[y, x] = census of left with margin tl; crr[y, w-1-x] = census of right with margin tr
    (mirrored rows).

    padl, padr, spadl, spadr: (h + ch - 1, w + cw - 1 + 64) uint8; smooth: (2, h, w) uint8;
    per-thread scratch byte (n, w + 64) uint8 and code (n, w) uint64; bounds: row stripes of
    the padded height."""
    h, w = left.shape
    rx, ry = cw // 2, ch // 2
    nstripes = bounds.shape[0] - 1
    for s in nb.prange(nstripes):
        _pad_rows(left, bounds[s], bounds[s + 1], rx, ry, padl)
        _pad_rows(right, bounds[s], bounds[s + 1], rx, ry, padr)
        y0, y1 = h * s // nstripes, h * (s + 1) // nstripes
        if tl > 0:
            _smooth_rows(left, y0, y1, smooth[0])
        if tr > 0:
            _smooth_rows(right, y0, y1, smooth[1])
    if tl > 0 or tr > 0:
        for s in nb.prange(nstripes):
            if tl > 0:
                _pad_rows(smooth[0], bounds[s], bounds[s + 1], rx, ry, spadl)
            if tr > 0:
                _pad_rows(smooth[1], bounds[s], bounds[s + 1], rx, ry, spadr)
    for s in nb.prange(nstripes):
        t = nb.get_thread_id()
        y0, y1 = h * s // nstripes, h * (s + 1) // nstripes
        for y in range(y0, y1):
            _census_row(padl, spadl, y, cw, ch, w, tl, byte[t], cl[y])
            _census_row(padr, spadr, y, cw, ch, w, tr, byte[t], code[t])
            c, out = code[t], crr[y]
            for x in range(w):
                out[w - 1 - x] = c[x]
