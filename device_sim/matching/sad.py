"""SAD block matching kernel: running sums, winner-take-all, texture, uniqueness, subpixel,
left-right check, valid-region border. Bit-exact with OpenCV's findStereoCorrespondenceBM.

Layout: rows are processed top to bottom inside a stripe (one stripe per thread, ``prange``).
``vs[c, j]`` holds the vertical (2r+1)-row sum of |P_L - P_R| for virtual column ``c`` and cost
index ``j`` (disparity = N - 1 + min_disparity - j); ``j`` is the contiguous innermost axis.
Each row updates ``vs`` column by column (add the row entering the window, subtract the row
leaving it) fused with the horizontal running sum that yields the window SAD for every ``j``.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .lanes import absdiff_u8, cast_like, cdiv, nadd, nmin, nsub, uidx
from .simd import slide_all, step_all, wta_all

_JIT = dict(nogil=True, cache=True, boundscheck=False, error_model="numpy")


@nb.njit(**_JIT)
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


@nb.njit(**_JIT)
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


@nb.njit(**_JIT)
def _row(pl: np.ndarray, pr: np.ndarray, y: int, upd: bool, r: int, cap: int, nd: int,
         min_disp: int, tex_thr: int, uratio: int, lofs: int, width1: int, lc: np.ndarray,
         rb: np.ndarray, vs: np.ndarray, ts: np.ndarray, sad: np.ndarray, big,
         recip: np.ndarray, drow: np.ndarray, crow: np.ndarray) -> None:
    """Disparities of row y for columns lofs .. lofs+width1-1 into drow (cost into crow)."""
    inv = (min_disp - 1) * 16
    zero = nsub(big, big)
    ya, ys = y + r, y - r - 1
    if upd:
        for ci in range(2 * r + 1):
            _slide_column(ci, pl, pr, ya, ys, cap, lc, rb, nd, vs, ts, zero)
    m = big
    for j in range(nd):
        sj = zero
        for ci in range(2 * r + 1):
            sj = nadd(sj, vs[ci, j])
        sad[j] = sj
        m = nmin(m, sj)
    tsum = 0
    for ci in range(2 * r + 1):
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
        X = uidx(lofs + x)
        if tsum < tex_thr:
            drow[X] = inv
            continue
        thr = cast_like(-1, big)  # uniqueness off: count nothing
        if uratio > 0:
            t = np.uint64(m) * np.uint64(uratio) // np.uint64(100) + np.uint64(m)
            thr = cast_like(min(t, np.uint64(big)), big)
        mind, cnt = wta_all(sad, nd, m, thr)
        # neighbours for the parabola; OpenCV mirrors them at the ends (sad[-1] := sad[1])
        inner = (mind > 0) & (mind < nd - 1)
        pi = mind + 1 if mind < nd - 1 else nd - 2
        ni = mind - 1 if mind > 0 else 1
        p = np.int32(sad[uidx(pi)])
        n = np.int32(sad[uidx(ni)])
        # uniqueness: no j outside mind-1 .. mind+1 may have sad[j] <= thr
        ok = cnt - 1 - (p <= thr) - (inner & (n <= thr)) <= 0
        # OpenCV: off = (p - n) * 256 / den truncated, den = p + n - 2m + |p - n|
        # = 2q with q = max(p, n) - m >= |p - n|, so off = +-(128 |p - n| / q)
        q = max(p, n) - np.int32(m)
        a128 = abs(p - n) * 128
        if recip.shape[0] > 0:
            off = (np.int64(a128) * recip[uidx(q)]) >> 40
        else:
            off = cdiv(a128, max(q, np.int32(1)))
        off = -off if p < n else off
        d = ((nd - mind - 1 + min_disp) * 256 + off + 15) >> 4
        drow[X] = d if ok else inv
        crow[X] = m


@nb.njit(**_JIT)
def _lr_check(drow: np.ndarray, crow: np.ndarray, x0: int, x1: int, inv: int, maxdiff: int,
              d2buf: np.ndarray, d2cost: np.ndarray) -> None:
    """OpenCV validateDisparity on one row (in place)."""
    for x in range(d2buf.shape[0]):
        d2buf[x] = inv
        d2cost[x] = 2147483647
    for x in range(x0, x1):
        d = drow[x]
        if d == inv:
            continue
        c = crow[x]
        x2 = x - ((d + 8) >> 4)
        if d2cost[x2] > c:
            d2cost[x2] = c
            d2buf[x2] = d
    w = d2buf.shape[0]
    md = maxdiff * 16
    for x in range(x0, x1):
        d = drow[x]
        if d == inv:
            continue
        xa = x - (d >> 4)
        xb = x - ((d + 15) >> 4)
        if (0 <= xa < w and d2buf[xa] > inv and abs(d2buf[xa] - d) > md
                and 0 <= xb < w and d2buf[xb] > inv and abs(d2buf[xb] - d) > md):
            drow[x] = inv


@nb.njit(parallel=True, **_JIT)
def match_rows(pl: np.ndarray, pr: np.ndarray, disp: np.ndarray, bounds: np.ndarray, r: int,
               cap: int, nd: int, min_disp: int, tex_thr: int, uratio: int, maxdiff: int,
               lofs: int, width1: int, roi_x0: int, roi_x1: int, lr_x0: int, lr_x1: int,
               lc: np.ndarray, rb: np.ndarray, vs: np.ndarray, ts: np.ndarray,
               sad: np.ndarray, big, recip: np.ndarray, drow: np.ndarray, crow: np.ndarray,
               d2buf: np.ndarray, d2cost: np.ndarray) -> None:
    """Rows bounds[s] .. bounds[s+1]-1 per stripe s; writes disp rows (roi only valid)."""
    h, w = disp.shape
    inv = (min_disp - 1) * 16
    nstripes = bounds.shape[0] - 1
    for s in nb.prange(nstripes):
        y0, y1 = bounds[s], bounds[s + 1]
        dr = drow[s]
        cr = crow[s]
        for y in range(y0, y1):
            if y == y0:
                _init_columns(pl, pr, y, r, cap, lc, rb, nd, vs[s], ts[s], nsub(big, big))
            for x in range(dr.shape[0]):
                dr[x] = inv
            _row(pl, pr, y, y != y0, r, cap, nd, min_disp, tex_thr, uratio, lofs, width1,
                 lc, rb, vs[s], ts[s], sad[s], big, recip, dr, cr)
            if maxdiff >= 0:
                _lr_check(dr, cr, lr_x0, lr_x1, inv, maxdiff, d2buf[s], d2cost[s])
            out = disp[y]
            for x in range(roi_x0):
                out[x] = inv
            for x in range(roi_x0, roi_x1):
                out[x] = dr[x]
            for x in range(roi_x1, w):
                out[x] = inv
            if y == h - r - 1:
                # OpenCV writes columns w .. lofs+width1-1 past the row end, i.e. into the
                # first columns of the next row, which no later step overwrites.
                for x in range(w, lofs + width1):
                    disp[y + 1, x - w] = dr[x]
