"""SGM kernel: Hamming costs, path aggregation, winner-take-all, uniqueness, subpixel and
left-right check, bit-exact with tests/sgm_reference.py.

Work split: two groups run in parallel (``prange(2)``). Group 0 walks the rows top to bottom
and owns the paths arriving from the left, from above and from the two upper diagonals; group
1 walks bottom to top with the mirrored paths. Per row a group computes its cost row from the
census codes, steps each of its paths (previous row's L kept per path, disparity axis
contiguous, int16) and sums them. The first group to finish a row parks its sum in ``S``; the
second adds it and finishes that row (winner-take-all ... left-right) into ``disp``. A per-row
spin lock decides who is first; nobody ever waits for the other group's progress, so one
thread runs the same code (group 0, then group 1) with the same result.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .lanes import uidx
from .sgm_simd import add_min, diag_update, path_step, popcount16, try_lock, unlock
from .simd import wta_all

_JIT = dict(nogil=True, cache=True, boundscheck=False, error_model="numpy")

# layout of the int64 configuration vector passed to sgm_rows
(C_ND, C_MIND, C_P1, C_P2, C_ADAPT, C_URATIO, C_LRDIFF, C_X0, C_COLS, C_PATHS, C_LEN) = range(11)


@nb.njit(**_JIT)
def _cost_row(cl: np.ndarray, crr: np.ndarray, y: int, x0: int, md: int, nd: int, cols: int,
              out: np.ndarray) -> None:
    """out[x * nd + k] = popcount(cl[y, x0 + x] ^ census_R[y, x0 + x - md - k])."""
    w = cl.shape[1]
    for x in range(cols):
        a = cl[y, uidx(x0 + x)]
        base = w - 1 - x0 - x + md
        o = x * nd
        for k in range(nd):
            out[uidx(o + k)] = popcount16(a ^ crr[y, uidx(base + k)])


@nb.njit(**_JIT)
def _p2(p1: int, p2: int, adapt: int, a: np.uint8, b: np.uint8) -> int:
    """Effective P2 between pixels of intensities a and b."""
    if adapt == 0:
        return p2
    return max(p1, p2 * adapt // (adapt + abs(np.int64(a) - np.int64(b))))


@nb.njit(**_JIT)
def _aggregate_row(g: int, y: int, first: bool, img: np.ndarray, cfg: np.ndarray,
                   cost: np.ndarray, hb: np.ndarray, lcur: np.ndarray, lprev: np.ndarray,
                   mcur: np.ndarray, mprev: np.ndarray, zero: np.ndarray,
                   acc: np.ndarray) -> None:
    """acc = sum over group g's paths of L at row y (lprev/mprev: the previous row's L and
    per-column minima, unused when first; lcur/mcur receive this row's)."""
    nd, p1, p2, adapt = cfg[C_ND], cfg[C_P1], cfg[C_P2], cfg[C_ADAPT]
    x0, cols = cfg[C_X0], cfg[C_COLS]
    nv = 1 if cfg[C_PATHS] == 4 else 3
    dy = 1 if g == 0 else -1
    stride = nd + 2
    q1 = np.int16(p1)
    start = np.int16(p2)  # any P2 >= 0 leaves L = C on a zero predecessor
    z = np.int16(0)
    hm = z
    for i in range(cols):
        x = i if g == 0 else cols - 1 - i
        X = x0 + x
        ci = x * nd
        cur = i & 1
        if i == 0:  # horizontal path (0, dy): predecessor x - dy on this row
            hm = path_step(cost, ci, zero, 1, hb[cur], 1, acc, ci, 1, q1, start, z, nd)
        else:
            e = _p2(p1, p2, adapt, img[y, X], img[y, X - dy])
            hm = path_step(cost, ci, hb[1 - cur], 1, hb[cur], 1, acc, ci, 1, q1,
                           np.int16(hm + e), hm, nd)
        for v in range(nv):  # paths (dy, 0), (dy, 1), (dy, -1): predecessor (y-dy, x-dx)
            dx = v if v < 2 else -1
            xq = x - dx
            oi = x * stride + 1
            if first or xq < 0 or xq >= cols:
                m = path_step(cost, ci, zero, 1, lcur[v], oi, acc, ci, 0, q1, start, z, nd)
            else:
                mp = mprev[v, xq]
                e = _p2(p1, p2, adapt, img[y, X], img[y - dy, X - dx])
                m = path_step(cost, ci, lprev[v], xq * stride + 1, lcur[v], oi, acc, ci, 0,
                              q1, np.int16(mp + e), mp, nd)
            mcur[v, x] = m


@nb.njit(**_JIT)
def _finish_row(y: int, cfg: np.ndarray, acc: np.ndarray, parked: np.ndarray,
                rmin: np.ndarray, rarg: np.ndarray, mins: np.ndarray,
                out: np.ndarray) -> None:
    """acc += parked (the other group's sum), then winner-take-all, uniqueness, left-right
    check and subpixel into the output row."""
    nd, md, uratio, lrdiff = cfg[C_ND], cfg[C_MIND], cfg[C_URATIO], cfg[C_LRDIFF]
    x0, cols = cfg[C_X0], cfg[C_COLS]
    inv = np.int16((md - 1) * 16)
    for i in range(rmin.shape[0]):
        rmin[i] = 32767
    for x in range(cols):
        mins[x] = add_min(acc, x * nd, parked, x * nd, nd)
        if lrdiff >= 0:
            diag_update(acc, x * nd, rmin, rarg, cols - 1 - x, nd)
    for x in range(x0):
        out[x] = inv
    for x in range(x0 + cols, out.shape[0]):
        out[x] = inv
    for x in range(cols):
        s = acc[x * nd:(x + 1) * nd]
        m = mins[x]
        thr = np.int16(-1)
        if uratio > 0:
            thr = np.int16(min(m + np.int64(m) * uratio // 100, 32767))
        k, cnt = wta_all(s, nd, m, thr)
        a = np.int64(s[uidx(k - 1)]) if k > 0 else np.int64(0)
        b = np.int64(s[uidx(k + 1)]) if k < nd - 1 else np.int64(0)
        near = np.int64((k > 0) & (a <= thr)) + np.int64((k < nd - 1) & (b <= thr))
        if uratio > 0 and cnt - 1 - near > 0:
            out[x0 + x] = inv
            continue
        if lrdiff >= 0 and abs(np.int64(rarg[uidx(cols - 1 - x + k)]) - k) > lrdiff:
            out[x0 + x] = inv
            continue
        d16 = 16 * (md + k)
        if 0 < k < nd - 1:
            den = max(a + b - 2 * np.int64(m), 1)
            d16 += ((a - b) * 16 + den) // (2 * den)
        out[x0 + x] = d16


@nb.njit(**_JIT)
def _group(g: int, img: np.ndarray, cl: np.ndarray, crr: np.ndarray, cfg: np.ndarray,
           parked: np.ndarray, locks: np.ndarray, done: np.ndarray, disp: np.ndarray,
           cost: np.ndarray, hb: np.ndarray, lv: np.ndarray, mv: np.ndarray, zero: np.ndarray,
           acc: np.ndarray, rmin: np.ndarray, rarg: np.ndarray, mins: np.ndarray) -> None:
    """Every row of group g (see the module docstring)."""
    h = img.shape[0]
    nd, md, x0, cols = cfg[C_ND], cfg[C_MIND], cfg[C_X0], cfg[C_COLS]
    for step in range(h):
        y = step if g == 0 else h - 1 - step
        cur = step & 1
        _cost_row(cl, crr, y, x0, md, nd, cols, cost)
        _aggregate_row(g, y, step == 0, img, cfg, cost, hb, lv[cur], lv[1 - cur], mv[cur],
                       mv[1 - cur], zero, acc)
        while not try_lock(locks, y):
            pass
        first = done[y] == 0
        if first:
            row = parked[y]
            for i in range(acc.shape[0]):
                row[i] = acc[i]
            done[y] = 1
        unlock(locks, y)
        if not first:
            _finish_row(y, cfg, acc, parked[y], rmin, rarg, mins, disp[y])


@nb.njit(parallel=True, **_JIT)
def sgm_rows(img: np.ndarray, cl: np.ndarray, crr: np.ndarray, cfg: np.ndarray,
             parked: np.ndarray, locks: np.ndarray, done: np.ndarray, disp: np.ndarray,
             cost: np.ndarray, hb: np.ndarray, lv: np.ndarray, mv: np.ndarray,
             zero: np.ndarray, acc: np.ndarray, rmin: np.ndarray, rarg: np.ndarray,
             mins: np.ndarray) -> None:
    """Disparity rows (before the speckle filter) of the census pair (cl, crr mirrored).

    Scratch has one slice per group (leading axis 2); locks and done must be zero."""
    for g in nb.prange(2):
        _group(g, img, cl, crr, cfg, parked, locks, done, disp, cost[g], hb[g], lv[g], mv[g],
               zero, acc[g], rmin[g], rarg[g], mins[g])
