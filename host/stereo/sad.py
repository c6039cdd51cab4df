"""SAD block matching kernel: running sums, winner-take-all, texture, uniqueness, subpixel,
left-right check and valid-region border, bit-exact with OpenCV's findStereoCorrespondenceBM.

Layout: each stripe of rows runs top to bottom on one thread (``prange`` over stripes, handed
out dynamically). ``vs[c, j]`` holds the vertical (2r+1)-row sum of |P_L - P_R| for virtual
column ``c`` (left column lofs + c, clamped as OpenCV clamps it) and cost index ``j``
(disparity = N - 1 + min_disparity - j); ``j`` is the contiguous innermost axis. For every
pixel one vector pass slides the column's vertical window down a row and the horizontal window
right a column (``simd.slide_all``), a second pass finds the first minimum and the uniqueness
count (``simd.wta_all``); the rest is scalar.

numba caches this module's kernels on disk keyed on *this* file only: after editing simd.py or
lanes.py, touch this file (or delete __pycache__) so the cache is rebuilt.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .jit import C_ARITHMETIC
from .lanes import absdiff_u8, cast_like, cdiv, nadd, nsub, uidx
from .simd import slide_all, step_all, wta_all

# layout of the int64 configuration vector passed to match_rows
(C_R, C_CAP, C_ND, C_MIND, C_TEX, C_URATIO, C_MAXDIFF, C_LOFS, C_WIDTH1, C_ROIX0, C_ROIX1,
 C_LRX0, C_LRX1, C_INV, C_LEN) = range(15)  # C_INV: the invalid code, params.invalid_value


@nb.njit(**C_ARITHMETIC)
def _init_columns(pl: np.ndarray, pr: np.ndarray, y: int, r: int, cap: int, lc: np.ndarray,
                  rb: np.ndarray, nd: int, vs: np.ndarray, ts: np.ndarray, zero) -> None:
    """Full vertical sums of every virtual column for the window centred on row y."""
    for ci in range(lc.shape[0]):
        for j in range(nd):
            vs[ci, j] = zero
        t = 0
        lcol, b = lc[ci], rb[ci]
        for k in range(y - r, y + r + 1):
            a = pl[k, lcol]
            for j in range(nd):
                vs[ci, j] = nadd(vs[ci, j], absdiff_u8(a, pr[k, uidx(b + j)], zero))
            t += abs(np.int32(a) - cap)
        ts[ci] = t


@nb.njit(**C_ARITHMETIC)
def _slide_column(ci: int, pl: np.ndarray, pr: np.ndarray, ya: int, ys: int, cap: int,
                  lc: np.ndarray, rb: np.ndarray, nd: int, vs: np.ndarray, ts: np.ndarray,
                  zero) -> None:
    """Slide column ci's vertical window: add row ya, remove row ys."""
    lcol, b = lc[ci], rb[ci]
    a = pl[ya, lcol]
    s = pl[ys, lcol]
    for j in range(nd):
        vs[ci, j] = nadd(vs[ci, j], nsub(absdiff_u8(a, pr[ya, uidx(b + j)], zero),
                                         absdiff_u8(s, pr[ys, uidx(b + j)], zero)))
    ts[ci] += abs(np.int32(a) - cap) - abs(np.int32(s) - cap)


@nb.njit(**C_ARITHMETIC)
def _row(pl: np.ndarray, pr: np.ndarray, y: int, upd: bool, cfg: np.ndarray, lc: np.ndarray,
         rb: np.ndarray, vs: np.ndarray, ts: np.ndarray, sad: np.ndarray, big,
         pix: np.ndarray) -> None:
    """Pass A of row y: per column x < width1, the first minimum of the window SADs.

    Writes pix[0..4, x] = (min SAD or -1 when the texture check fails, its index, the number
    of SADs <= the uniqueness threshold, the SADs at index+1 and index-1 as OpenCV mirrors
    them). upd: slide the vertical sums down from row y-1 (False on a stripe's first row,
    whose sums _init_columns has just built)."""
    r, cap, nd = cfg[C_R], cfg[C_CAP], cfg[C_ND]
    tex_thr, uratio, width1 = cfg[C_TEX], cfg[C_URATIO], cfg[C_WIDTH1]
    zero = nsub(big, big)
    ya, ys = y + r, y - r - 1
    wsz = 2 * r + 1
    if upd:
        for ci in range(wsz):
            _slide_column(ci, pl, pr, ya, ys, cap, lc, rb, nd, vs, ts, zero)
    for j in range(nd):
        sj = zero
        for ci in range(wsz):
            sj = nadd(sj, vs[ci, j])
        sad[j] = sj
    m = big
    for j in range(nd):
        m = min(m, sad[j])
    tsum = 0
    for ci in range(wsz):
        tsum += ts[ci]
    for x in range(width1):
        ci = x + 2 * r
        if x > 0:
            if upd:
                lcol, b = lc[uidx(ci)], rb[uidx(ci)]
                a = pl[ya, uidx(lcol)]
                s = pl[ys, uidx(lcol)]
                m = slide_all(vs, ci, x - 1, sad, pr, ya, ys, b, a, s, nd)
                ts[uidx(ci)] += abs(np.int32(a) - cap) - abs(np.int32(s) - cap)
            else:
                m = step_all(vs, ci, x - 1, sad, nd)
            tsum += ts[uidx(ci)] - ts[uidx(x - 1)]
        xu = uidx(x)
        if tsum < tex_thr:  # texture is checked first, as in OpenCV
            pix[0, xu] = -1
            continue
        thr = cast_like(-1, big)  # uniqueness off: count nothing
        if uratio > 0:
            t = np.uint64(m) * np.uint64(uratio) // np.uint64(100) + np.uint64(m)
            thr = cast_like(min(t, np.uint64(big)), big)
        mind, cnt = wta_all(sad, nd, m, thr)  # first minimum; #{j: sad[j] <= thr}
        pix[0, xu] = m
        pix[1, xu] = mind
        pix[2, xu] = cnt
        # parabola neighbours; OpenCV mirrors them at the ends (sad[-1] := sad[1], ...)
        pix[3, xu] = sad[uidx(mind + 1 if mind < nd - 1 else nd - 2)]
        pix[4, xu] = sad[uidx(mind - 1 if mind > 0 else 1)]


@nb.njit(**C_ARITHMETIC)
def _finish_row(cfg: np.ndarray, big, pix: np.ndarray, drow: np.ndarray,
                crow: np.ndarray) -> None:
    """Pass B (vectorised over x): uniqueness verdict, subpixel offset, output values."""
    nd, min_disp, uratio = cfg[C_ND], cfg[C_MIND], cfg[C_URATIO]
    lofs, width1 = cfg[C_LOFS], cfg[C_WIDTH1]
    inv = cfg[C_INV]
    top = np.int64(big)
    base = (nd - 1 + min_disp) * 256 + 15
    for x in range(width1):
        m = np.int64(pix[0, x])
        k = np.int64(pix[1, x])
        p = np.int64(pix[3, x])
        n = np.int64(pix[4, x])
        thr = min(m + cdiv(m * uratio, np.int64(100)), top)  # m >= 0 where it matters
        thr = thr if uratio > 0 else np.int64(-1)
        inner = (k > 0) & (k < nd - 1)
        # uniqueness: no j outside mind-1 .. mind+1 may have sad[j] <= thr
        ok = (m >= 0) & (np.int64(pix[2, x]) - 1 - (p <= thr) - (inner & (n <= thr)) <= 0)
        # OpenCV: off = (p - n) * 256 / den truncated, den = p + n - 2m + |p - n|
        # = 2q with q = max(p, n) - m >= |p - n|, so off = +-(128 |p - n| / q); the float64
        # quotient truncates exactly (its error is far below 1/q)
        q = max(max(p, n) - m, np.int64(1))
        off = np.int64(np.float64(abs(p - n) * 128) / np.float64(q))
        off = -off if p < n else off
        d = (base - k * 256 + off) >> 4
        X = uidx(lofs + x)
        drow[X] = d if ok else inv
        crow[X] = m


@nb.njit(**C_ARITHMETIC)
def _lr_check(drow: np.ndarray, crow: np.ndarray, x0: int, x1: int, inv: int, maxdiff: int,
              d2buf: np.ndarray, d2cost: np.ndarray) -> None:
    """OpenCV validateDisparity on one row (in place)."""
    w = d2buf.shape[0]
    for x in range(w):
        d2buf[x] = inv
        d2cost[x] = 2147483647
    for x in range(x0, x1):
        d = np.int32(drow[x])
        if d == inv:
            continue
        c = crow[x]
        x2 = uidx(x - ((d + 8) >> 4))
        if d2cost[x2] > c:
            d2cost[x2] = c
            d2buf[x2] = d
    md = maxdiff * 16
    for x in range(x0, x1):
        d = np.int32(drow[x])
        if d == inv:
            continue
        xa = x - (d >> 4)
        xb = x - ((d + 15) >> 4)
        if (0 <= xa < w and d2buf[uidx(xa)] > inv and abs(d2buf[uidx(xa)] - d) > md
                and 0 <= xb < w and d2buf[uidx(xb)] > inv and abs(d2buf[uidx(xb)] - d) > md):
            drow[x] = inv


@nb.njit(parallel=True, **C_ARITHMETIC)
def match_rows(pl: np.ndarray, pr: np.ndarray, disp: np.ndarray, bounds: np.ndarray,
               cfg: np.ndarray, lc: np.ndarray, rb: np.ndarray, big, vs: np.ndarray,
               ts: np.ndarray, sad: np.ndarray, pix: np.ndarray, drow: np.ndarray,
               crow: np.ndarray, d2buf: np.ndarray, d2cost: np.ndarray) -> None:
    """Rows bounds[s] .. bounds[s+1]-1 of stripe s into disp (valid region only).

    Scratch arrays have one slice per thread (leading axis >= the active thread count)."""
    h, w = disp.shape
    r, nd, maxdiff = cfg[C_R], cfg[C_ND], cfg[C_MAXDIFF]
    roi_x0, roi_x1 = cfg[C_ROIX0], cfg[C_ROIX1]
    inv = cfg[C_INV]
    spill = cfg[C_LOFS] + cfg[C_WIDTH1]
    for s in nb.prange(bounds.shape[0] - 1):
        t = nb.get_thread_id()
        y0, y1 = bounds[s], bounds[s + 1]
        dr, cr = drow[t], crow[t]
        for y in range(y0, y1):
            if y == y0:
                _init_columns(pl, pr, y, r, cfg[C_CAP], lc, rb, nd, vs[t], ts[t],
                              nsub(big, big))
            for x in range(dr.shape[0]):
                dr[x] = inv
            _row(pl, pr, y, y != y0, cfg, lc, rb, vs[t], ts[t], sad[t], big, pix[t])
            _finish_row(cfg, big, pix[t], dr, cr)
            if maxdiff >= 0:
                _lr_check(dr, cr, cfg[C_LRX0], cfg[C_LRX1], inv, maxdiff, d2buf[t], d2cost[t])
            out = disp[y]
            for x in range(roi_x0):
                out[x] = inv
            for x in range(roi_x0, roi_x1):
                out[x] = dr[x]
            for x in range(roi_x1, w):
                out[x] = inv
            if y == h - r - 1:
                # OpenCV writes columns w .. lofs+width1-1 (min_disparity > 0) past the row
                # end, i.e. into the first columns of row h - r, which nothing overwrites.
                for x in range(w, spill):
                    disp[y + 1, x - w] = dr[x]
