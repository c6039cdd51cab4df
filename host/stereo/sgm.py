"""SGM kernel: Hamming costs, path aggregation, winner-take-all, uniqueness, subpixel and
left-right check, bit-exact with tests/support/sgm_reference.py; the row stages here, 4 and 8
paths run by sgm_rows, 5 paths by sgm_one_pass.py.

Work split of 4 and 8 paths: two groups run in parallel (``prange(2)``). Group 0 walks the rows top to bottom
and owns the paths arriving from the left, from above and from the two upper diagonals; group
1 walks bottom to top with the mirrored paths. Per row a group computes its cost row from the
census codes, steps all its paths in one pass per pixel (sgm_simd.pixel_paths: uint8 path
costs, the previous row's kept per path, the disparity axis contiguous) and sums them in
int16. The first group to finish a row parks its sum in ``parked``; the second adds it and
finishes that row (winner-take-all ... left-right) into ``disp``. A per-row spin lock decides
who is first; nobody ever waits for the other group's progress, so one thread runs the same
code (group 0, then group 1) with the same result.

numba's disk cache of these kernels is keyed on every module of the package (jit.py), so
editing sgm_simd.py, census.py or postfilter.py rebuilds them.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .atomics import spin_wait, try_lock, unlock
from .jit import C_ARITHMETIC
from .lanes import uidx
from .census_simd import cost_run
from .sgm_simd import add_argmin, count_le, diag_update, path_step, pixel_paths, stream_copy, \
    sum_pos

_JIT = C_ARITHMETIC

# layout of the int64 configuration vector passed to sgm_rows
(C_ND, C_MIND, C_P1, C_URATIO, C_LRDIFF, C_X0, C_COLS, C_PATHS, C_INV, C_OUTC, C_CW, C_CH,
 C_SPW, C_SPR, C_TL, C_TR, C_P1G, C_LEN) = range(18)
# C_INV: params.invalid_value; C_OUTC: params.outside_cost; C_CW, C_CH: census window; C_SPW,
# C_SPR: speckle window size (0: no speckle filter) and range; C_TL, C_TR: the frame's census
# margins of the left and right image (set per frame); C_P1G: params.p1_ground_step; after C_LEN
# the places of the nd sums in split order (sum_places), cfg[C_LEN + 1 + k] for disparity k, 0 at
# C_LEN and C_LEN + nd + 1 (the winner's neighbours are looked up there, not computed per pixel)
NO_P2 = 0xFFFFFFFF  # pixel_paths' q of a path's first pixel (no predecessor): P2 255 in each byte


def sum_places(nd: int) -> np.ndarray:
    """The tail of the configuration vector after C_LEN: 0, sum_pos(k, nd) for k < nd, 0."""
    return np.array([0, *(sum_pos(k, nd) for k in range(nd)), 0], np.int64)


@nb.njit(inline="always", **_JIT)
def run_stride(nd: int) -> int:
    """Elements from one path-cost run (nd uint8 costs of a pixel) to the next in lbuf: nd
    rounded up to 64, so every run starts on a cache line (with 64-byte lbuf) and a path step
    that reads the run the previous pixel's step just wrote gets it forwarded from the store
    (a store split across two cache lines is not forwarded: the step then waits for it to
    reach the cache)."""
    return (nd + 63) & ~63


@nb.njit(**_JIT)
def _inside(X: int, md: int, nd: int) -> int:
    """Disparities of left column X whose right pixel is in the image (k <= X - md), rounded
    up to cost_run's 16 lanes, at most nd: the rest are the constant outc, not computed."""
    return min(nd, (X - md + 16) & ~15)


@nb.njit(**_JIT)
def _cost_row(cl: np.ndarray, crr: np.ndarray, y: int, x0: int, md: int, nd: int, cols: int,
              outc: int, out: np.ndarray) -> None:
    """out[x * nd + k] = popcount(census_L[y, x0 + x] ^ census_R[y, x0 + x - md - k]), or outc
    where that right pixel is left of the image (cl[y], crr[y]: their byte planes, census_R's
    mirrored and running nd codes past it)."""
    w = cl.shape[2]
    for x in range(cols):
        cost_run(cl[y], x0 + x, crr[y], w - 1 - x0 - x + md, out, x * nd,
                 _inside(x0 + x, md, nd))
    for x in range(min(cols, nd - 1 - x0 + md)):  # k > x0 + x - md is outside
        out[x * nd + x0 + x - md + 1:(x + 1) * nd] = outc


@nb.njit(**_JIT)
def _aggregate_row(g: int, y: int, first: bool, npaths: int, hb: int, kept: int, vb: int,
                   cur: int, prv: int, i0: int, i1: int, img: np.ndarray, cfg: np.ndarray,
                   p2tab: np.ndarray, cost: np.ndarray, lbuf: np.ndarray, mv: np.ndarray,
                   pm: np.ndarray, acc: np.ndarray) -> None:
    """acc = sum of the paths of L at row y, pixels i0 .. i1-1 in path order: the horizontal
    path (left to right for g = 0, right to left for g = 1), then (npaths 2 or 4) the
    vertical and diagonal paths arriving from the row above (g = 0) or below (g = 1), none
    on the first; npaths 5: four paths plus the one _kept_rows kept.

    lbuf runs of run_stride(nd), 64-aligned: from hb, two for the horizontal path
    (this pixel's and its predecessor's) and one zero run (predecessor of a path's first
    pixel); for npaths 5 from kept, the kept path's one per column (_kept_rows); from vb,
    per row slot and vertical/diagonal path one run per column, row y in slot cur, its
    predecessor row in prv. mv[slot, v, x]: minima, times 0x01010101 (pixel_paths' form).
    p2tab[0, 255 + I(p) - I(q)]: the effective P2 between neighbours of those intensities
    (indexed by the signed step: no absolute value per lookup); p2tab[1] the same times
    0x01010101."""
    nd, p1 = cfg[C_ND], cfg[C_P1]
    x0, cols = cfg[C_X0], cfg[C_COLS]
    dy = 1 if g == 0 else -1
    # vertical/diagonal paths in the lower half: the ground's step (disparity growing downwards)
    # costs C_P1G
    p1v = (p1, p1) if 2 * y < img.shape[0] else (cfg[C_P1G], p1) if dy > 0 else (p1, cfg[C_P1G])
    stride = run_stride(nd)
    vpaths = min(npaths, 4)
    if first:  # no predecessor row: every pixel takes the general way
        for i in range(i0, i1):
            _aggregate_pixel(i, g, y, True, npaths, hb, kept, vb, cur, prv, img, cfg, p2tab,
                             cost, lbuf, mv, pm, acc, p1v)
        return
    # the row's first and last pixels (a predecessor outside the row) the general way, the
    # others with every predecessor inside: no tests, the per-row bases hoisted
    lo, hi = max(i0, 1), min(i1, cols - 1)
    if i0 == 0:
        _aggregate_pixel(0, g, y, False, npaths, hb, kept, vb, cur, prv, img, cfg, p2tab,
                         cost, lbuf, mv, pm, acc, p1v)
    irow, prow = img[y], img[y - dy]
    bp = (vb + prv * 3 * cols * stride, vb + (prv * 3 + 1) * cols * stride,
          vb + (prv * 3 + 2) * cols * stride)
    bc = (vb + cur * 3 * cols * stride, vb + (cur * 3 + 1) * cols * stride,
          vb + (cur * 3 + 2) * cols * stride)
    mp0, mp1, mp2 = mv[prv, 0], mv[prv, 1], mv[prv, 2]
    mc0, mc1, mc2 = mv[cur, 0], mv[cur, 1], mv[cur, 2]
    for i in range(lo, hi):
        x = i if g == 0 else cols - 1 - i
        X = x0 + x
        ic = np.int64(irow[uidx(X)])
        mh = np.int64(pm[0])  # horizontal path: predecessor x - dy on this row
        hz = (hb + (1 - (i & 1)) * stride, hb + (i & 1) * stride,
              p2tab[1, uidx(255 + ic - irow[uidx(X - dy)])], mh)
        m1 = np.int64(mp0[uidx(x)])  # (dy, 0), (dy, 1), (dy, -1): predecessor (y - dy, x - dx)
        v1 = (bp[0] + x * stride, bc[0] + x * stride,
              p2tab[1, uidx(255 + ic - prow[uidx(X)])], m1)
        v2 = v3 = v1
        if vpaths > 2:
            m2 = np.int64(mp1[uidx(x - 1)])
            v2 = (bp[1] + (x - 1) * stride, bc[1] + x * stride,
                  p2tab[1, uidx(255 + ic - prow[uidx(X - 1)])], m2)
            m3 = np.int64(mp2[uidx(x + 1)])
            v3 = (bp[2] + (x + 1) * stride, bc[2] + x * stride,
                  p2tab[1, uidx(255 + ic - prow[uidx(X + 1)])], m3)
        pixel_paths(cost, x * nd, lbuf, hz + v1 + v2 + v3 + (kept + x * stride,), npaths, p1,
                    acc, x * nd, nd, pm, p1v)
        mc0[uidx(x)] = pm[1]
        if vpaths > 2:
            mc1[uidx(x)] = pm[2]
            mc2[uidx(x)] = pm[3]
    if i1 == cols and cols > 1:
        _aggregate_pixel(cols - 1, g, y, False, npaths, hb, kept, vb, cur, prv, img, cfg,
                         p2tab, cost, lbuf, mv, pm, acc, p1v)


@nb.njit(**_JIT)
def _aggregate_pixel(i: int, g: int, y: int, first: bool, npaths: int, hb: int, kept: int,
                     vb: int, cur: int, prv: int, img: np.ndarray, cfg: np.ndarray,
                     p2tab: np.ndarray, cost: np.ndarray, lbuf: np.ndarray, mv: np.ndarray,
                     pm: np.ndarray, acc: np.ndarray, p1v: tuple) -> None:
    """Pixel i (in path order) of _aggregate_row, any predecessor outside the image taken
    as none (the zero run, P2 255, minimum 0)."""
    nd, p1 = cfg[C_ND], cfg[C_P1]
    x0, cols = cfg[C_X0], cfg[C_COLS]
    dy = 1 if g == 0 else -1
    stride = run_stride(nd)
    zero = hb + 2 * stride
    vpaths = min(npaths, 4)
    x = i if g == 0 else cols - 1 - i
    X = x0 + x
    # horizontal path (0, dy): predecessor x - dy on this row
    po, pv, mp = zero, NO_P2, np.int64(0)
    if i > 0:
        mp = np.int64(pm[0])
        po = hb + (1 - (i & 1)) * stride
        pv = p2tab[1, uidx(255 + np.int64(img[y, uidx(X)]) - img[y, uidx(X - dy)])]
    hz = (po, hb + (i & 1) * stride, pv, mp)
    # (dy, 0), (dy, 1), (dy, -1): predecessor (y - dy, x - dx)
    v1 = _vertical_meta(1, 0, first, x, X, y, dy, cur, prv, vb, zero, cols, stride, img,
                        p2tab, mv)
    v2 = v3 = v1
    if vpaths > 2:
        v2 = _vertical_meta(2, 1, first, x, X, y, dy, cur, prv, vb, zero, cols, stride,
                            img, p2tab, mv)
        v3 = _vertical_meta(3, -1, first, x, X, y, dy, cur, prv, vb, zero, cols, stride,
                            img, p2tab, mv)
    pixel_paths(cost, x * nd, lbuf, hz + v1 + v2 + v3 + (kept + x * stride,), npaths, p1, acc,
                x * nd, nd, pm, p1v)
    for v in range(1, vpaths):
        mv[cur, v - 1, uidx(x)] = pm[v]


@nb.njit(inline="always", **_JIT)
def _vertical_meta(v: int, dx: int, first: bool, x: int, X: int, y: int, dy: int, cur: int,
                   prv: int, vb: int, zero: int, cols: int, stride: int, img: np.ndarray,
                   p2tab: np.ndarray, mv: np.ndarray) -> tuple[int, int, int, int]:
    """pixel_paths' (po, oo, q, m) of vertical/diagonal path v (_aggregate_row); with no
    predecessor the zero run, P2 255 and minimum 0."""
    xq = x - dx
    oo = vb + ((cur * 3 + v - 1) * cols + x) * stride
    if first or xq < 0 or xq >= cols:
        return zero, oo, NO_P2, np.int64(0)
    mp = np.int64(mv[prv, v - 1, uidx(xq)])
    return (vb + ((prv * 3 + v - 1) * cols + xq) * stride, oo,
            p2tab[1, uidx(255 + np.int64(img[y, uidx(X)]) - img[uidx(y - dy), uidx(X - dx)])], mp)


@nb.njit(**_JIT)
def _kept_rows(g: int, y0: int, y1: int, hb: int, img: np.ndarray, cl: np.ndarray,
               crr: np.ndarray, cfg: np.ndarray, p2tab: np.ndarray, cost: np.ndarray,
               lbuf: np.ndarray) -> None:
    """Cost rows y0 and y1 (as _cost_row; y1 < 0: y0 only; y1's from cost[cols * nd]) and,
    pixel by pixel as the costs are made, each row's horizontal path (left to right for
    g = 0, right to left for g = 1) kept per column in lbuf: y0's runs from hb + 3
    run_stride(nd), y1's cols runs further (_aggregate_row's kept). Two rows in one loop:
    a path step waits on its predecessor's minimum, so one path alone leaves the core idle
    between steps, and the other row's step fills it."""
    nd, md, p1 = cfg[C_ND], cfg[C_MIND], cfg[C_P1]
    x0, cols, outc = cfg[C_X0], cfg[C_COLS], cfg[C_OUTC]
    w = cl.shape[2]
    stride = run_stride(nd)
    k0, zero = hb + 3 * stride, hb + 2 * stride
    k1, o1 = k0 + cols * stride, cols * nd
    two = y1 >= 0
    dy = 1 if g == 0 else -1
    outside = nd - 1 - x0 + md  # columns x < outside have disparities left of the image
    hm0 = hm1 = np.int64(0)
    for i in range(cols):
        x = i if g == 0 else cols - 1 - i
        X = x0 + x
        inside = _inside(X, md, nd)
        cost_run(cl[y0], X, crr[y0], w - 1 - X + md, cost, x * nd, inside)
        if two:
            cost_run(cl[y1], X, crr[y1], w - 1 - X + md, cost, o1 + x * nd, inside)
        if x < outside:
            cost[x * nd + X - md + 1:(x + 1) * nd] = outc
            if two:
                cost[o1 + x * nd + X - md + 1:o1 + (x + 1) * nd] = outc
        if i == 0:
            hm0 = path_step(cost, x * nd, lbuf, zero, k0 + x * stride, 255, 0, p1, nd)
            if two:
                hm1 = path_step(cost, o1 + x * nd, lbuf, zero, k1 + x * stride, 255, 0, p1, nd)
        else:
            p2m = min(hm0 + p2tab[0, uidx(255 + np.int64(img[y0, X]) - img[y0, X - dy])], 255)
            hm0 = path_step(cost, x * nd, lbuf, k0 + (x - dy) * stride, k0 + x * stride,
                            p2m, hm0, p1, nd)
            if two:
                p2m = min(hm1 + p2tab[0, uidx(255 + np.int64(img[y1, X]) - img[y1, X - dy])], 255)
                hm1 = path_step(cost, o1 + x * nd, lbuf, k1 + (x - dy) * stride,
                                k1 + x * stride, p2m, hm1, p1, nd)


@nb.njit(**_JIT)
def _finish_row(y: int, cfg: np.ndarray, acc: np.ndarray, parked: np.ndarray | None,
                rmin: np.ndarray, rarg: np.ndarray, karg: np.ndarray,
                out: np.ndarray) -> None:
    """acc += parked (the other group's sum; None: acc is the whole sum), then per pixel
    winner-take-all and uniqueness in one pass (the sum stays in L1), keeping in karg (int32,
    3 x cols) the winner, the equiangular subpixel fraction's numerator and denominator (0:
    invalid); then the disparities in a second pass, whose divisions vectorise; and the
    left-right check, which needs the whole row's right-image winners."""
    nd, md, uratio, lrdiff = cfg[C_ND], cfg[C_MIND], cfg[C_URATIO], cfg[C_LRDIFF]
    x0, cols = cfg[C_X0], cfg[C_COLS]
    inv = np.int16(cfg[C_INV])
    kk, num, den = karg[0], karg[1], karg[2]
    for x in range(x0):
        out[x] = inv
    for x in range(x0 + cols, out.shape[0]):
        out[x] = inv
    if lrdiff >= 0:
        for i in range(rmin.shape[0]):
            rmin[i] = 32767
    pos = cfg[C_LEN:]  # pos[1 + k]: where disparity k's sum sits (a table: 0-3 % of a frame saved)
    for x in range(cols):
        o = x * nd
        m, k = add_argmin(acc, o, parked, o, nd)
        if lrdiff >= 0:
            diag_update(acc, o, rmin, rarg, cols - 1 - x, nd)
        kk[x] = k
        a = np.int64(acc[uidx(o + pos[k])]) if k > 0 else np.int64(0)
        b = np.int64(acc[uidx(o + pos[k + 2])]) if k < nd - 1 else np.int64(0)
        if uratio > 0:
            thr = min(m + m * uratio // 100, 32767)
            near = np.int64((k > 0) & (a <= thr)) + np.int64((k < nd - 1) & (b <= thr))
            if count_le(acc, o, nd, thr) - 1 - near > 0:
                den[x] = 0
                continue
        if 0 < k < nd - 1:
            d = max(max(a, b) - m, 1)  # equiangular (parabola: pixel-locking bias)
            num[x] = (a - b) * 16 + d
            den[x] = 2 * d
        else:
            num[x] = 0
            den[x] = 1
    for x in range(cols):
        # floor(num / den) exactly: |num| < 2^20, den < 2^17, so a quotient that is not a
        # whole number is 1 / den (> 2^-17) from one, far beyond float64's rounding
        q = np.floor(np.float64(num[x]) / np.float64(max(den[x], 1)))
        d16 = 16 * (md + np.int64(kk[x])) + np.int64(q)
        out[uidx(x0 + x)] = d16 if den[x] != 0 else inv
    if lrdiff >= 0:
        for x in range(cols):
            k = np.int64(kk[x])
            if out[x0 + x] != inv and abs(np.int64(rarg[uidx(cols - 1 - x + k)]) - k) > lrdiff:
                out[x0 + x] = inv


@nb.njit(**_JIT)
def _group(g: int, img: np.ndarray, cl: np.ndarray, crr: np.ndarray, cfg: np.ndarray,
           p2tab: np.ndarray, parked: np.ndarray, locks: np.ndarray, done: np.ndarray,
           disp: np.ndarray, cost: np.ndarray, lbuf: np.ndarray, mv: np.ndarray,
           pm: np.ndarray, acc: np.ndarray, rmin: np.ndarray,
           rarg: np.ndarray, karg: np.ndarray) -> None:
    """Every row of group g (see the module docstring)."""
    h = img.shape[0]
    nd, md, x0, cols = cfg[C_ND], cfg[C_MIND], cfg[C_X0], cfg[C_COLS]
    for step in range(h):
        y = step if g == 0 else h - 1 - step
        _cost_row(cl, crr, y, x0, md, nd, cols, cfg[C_OUTC], cost)
        _aggregate_row(g, y, step == 0, 2 if cfg[C_PATHS] == 4 else 4, 0, 0,
                       3 * run_stride(nd), step & 1, 1 - (step & 1), 0, cols, img, cfg, p2tab,
                       cost, lbuf, mv, pm, acc)
        n = 0
        while not try_lock(locks, y):
            n += 1
            spin_wait(n)
        first = done[y] == 0
        if first:
            stream_copy(parked[y], acc, acc.shape[0])
            done[y] = 1
        unlock(locks, y)
        if not first:
            _finish_row(y, cfg, acc, parked[y], rmin, rarg, karg, disp[y])


@nb.njit(parallel=True, **_JIT)
def sgm_rows(img: np.ndarray, cl: np.ndarray, crr: np.ndarray, cfg: np.ndarray,
             p2tab: np.ndarray, parked: np.ndarray, locks: np.ndarray, done: np.ndarray,
             disp: np.ndarray, cost: np.ndarray, lbuf: np.ndarray, mv: np.ndarray,
             pm: np.ndarray, acc: np.ndarray, rmin: np.ndarray, rarg: np.ndarray,
             karg: np.ndarray) -> None:
    """Disparity rows (before the speckle filter) of the census pair (cl; crr, byte planes,
    mirrored: census.census_pair).

    Scratch has one slice per group (leading axis 2); locks and done must be zero."""
    for g in nb.prange(2):
        _group(g, img, cl, crr, cfg, p2tab, parked, locks, done, disp, cost[g], lbuf[g], mv[g],
               pm[g], acc[g], rmin[g], rarg[g], karg[g])
