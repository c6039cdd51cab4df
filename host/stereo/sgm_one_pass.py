"""SGM with 5 paths in one pass per image half (sgm_single_pass), on sgm.py's row stages.

No volume is stored: one pass per half of the image, the top half top to bottom with the
paths from above, the bottom half bottom to top with those from below, two rows at a time:
each row making its census codes and cost row once, the right-to-left path kept per column
(both rows' in one loop, so that one path's steps fill the other's waits), then per row left
to right the other four paths, the sum and the selection; whoever finishes a half runs its
part of the speckle filter (the second also the seam's). Everything runs in that one
parallel region: the halves are independent chains (one per worker); a worker whose chain is
done takes the other over after its rows in progress (with two workers), and with more
workers each chain has several; rows within a chain wait band by band on the row before (a
per-row progress count; a bounded spin, then yielding the core). A pool worker that finds
itself on another worker's CPU moves off it for the frame (cpus.spread_out; the caller gives
it its mask back after the frame, cpus.restore).

numba's disk cache of these kernels is keyed on every module of the package (jit.py).
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .atomics import fetch_add, load_acquire, spin_wait, store_release
from .census import census_row_pair
from .cpus import STAY, restore, spread_out
from .jit import C_ARITHMETIC
from .postfilter import clear_seam, join_seam, label_band
from .sgm import C_CH, C_COLS, C_CW, C_INV, C_ND, C_SPR, C_SPW, C_TL, C_TR, _aggregate_row, \
    _finish_row, _kept_rows, run_stride

_JIT = C_ARITHMETIC

BAND = 32  # columns a row publishes its progress after (single-pass mode), with more than one
# worker: alone, a worker steps each row in one call (a call per band costs ~3 ns a pixel)
NXT_STRIDE = 16  # nxt[c * NXT_STRIDE]: chain c's next row, each on its own cache line;
# nxt[(2 + c) * NXT_STRIDE]: its rows finished; nxt[4 * NXT_STRIDE]: halves speckle-labelled;
# nxt[(5 + c) * NXT_STRIDE]: chain c handed to the worker that joined it
NXT_SLOTS = 7


@nb.njit(**_JIT)
def area_runs(cols: int) -> int:
    """Runs (run_stride each) of a worker's horizontal-path area in lbuf: two for the
    horizontal path, a zero run, then two rows' kept paths of cols runs each (_kept_rows)."""
    return 2 * cols + 3


@nb.njit(**_JIT)
def _chain_rows(c: int, j: int, n: int, hb: int, vb: int, img: np.ndarray, right: np.ndarray,
                cl: np.ndarray, crr: np.ndarray, cfg: np.ndarray, p2tab: np.ndarray,
                prog: np.ndarray, disp: np.ndarray, win: tuple, offs: np.ndarray,
                cost: np.ndarray, lbuf: np.ndarray, mv: np.ndarray,
                pm: np.ndarray, acc: np.ndarray, rmin: np.ndarray,
                rarg: np.ndarray, karg: np.ndarray, band: int) -> None:
    """Rows j .. j + n - 1 (n 1 or 2) of chain c (c = 0: the top half top-down, paths from
    above; c = 1: the bottom half bottom-up, paths from below): the rows' census codes
    (census_row_pair; win its scratch, offs its table), their cost rows and one horizontal
    path each kept per column in lbuf (_kept_rows, both rows in one loop), then per row in
    the other horizontal direction the other four paths plus the kept one into acc, band
    by band (``band`` columns) once the chain's previous row has published (prog) the
    columns the band reads, and the selection. hb: this worker's horizontal-path area
    (area_runs); vb: the chain's three row slots of three paths; cost: this worker's two
    cost rows."""
    h = img.shape[0]
    nd, cols = cfg[C_ND], cfg[C_COLS]
    stride = run_stride(nd)
    dy = 1 - 2 * c
    y0 = j if c == 0 else h - 1 - j
    for r in range(n):
        census_row_pair(img, right, y0 + r * dy, cfg[C_CW], cfg[C_CH], cfg[C_TL], cfg[C_TR],
                        win, offs, cl, crr)
    _kept_rows(1 - c, y0, y0 + dy if n == 2 else -1, hb, img, cl, crr, cfg, p2tab, cost, lbuf)
    for r in range(n):
        jr, y = j + r, y0 + r * dy
        costr = cost[r * cols * nd:(r + 1) * cols * nd]
        kept = hb + (3 + r * cols) * stride
        i = 0
        while i < cols:
            i1 = min(i + band, cols)
            if jr > 0:
                need = min(i1 + 1, cols)
                k = 0
                while load_acquire(prog, y - dy) < need:  # more than two workers share a chain
                    k += 1
                    spin_wait(k)
            _aggregate_row(c, y, jr == 0, 5, hb, kept, vb, jr % 3, (jr + 2) % 3, i, i1, img,
                           cfg, p2tab, costr, lbuf, mv, pm, acc)
            store_release(prog, y, i1)
            i = i1
        _finish_row(y, cfg, acc, None, rmin, rarg, karg, disp[y])


@nb.njit(**_JIT)
def _single_pass(t: int, img: np.ndarray, right: np.ndarray, cl: np.ndarray, crr: np.ndarray,
                 cfg: np.ndarray, p2tab: np.ndarray, nxt: np.ndarray, prog: np.ndarray,
                 disp: np.ndarray, win: tuple, offs: np.ndarray,
                 cost: np.ndarray, lbuf: np.ndarray, mv: np.ndarray,
                 pm: np.ndarray, acc: np.ndarray, rmin: np.ndarray, rarg: np.ndarray,
                 karg: np.ndarray, spk: tuple, workers: int, spread: tuple) -> None:
    """Worker t: rows of chain t % 2 taken two at a time until none is left (_chain_rows),
    then, with one or two workers, the other chain over: its worker stops after the rows in
    progress (the flag at (5 + c) * NXT_STRIDE) and this one does the rest, each row waiting
    band by band on the one before. So when one of two workers lags (descheduled, or sharing
    its CPU), the one done first finishes the frame at its own speed. With more workers each
    stays on its chain. Whoever finishes a half's last row filters its speckles
    (_speckle_half). spread: (where, masks, caller) of cpus.spread_out, called per two rows
    until it decides (sgm_single_pass restores the masks)."""
    h = img.shape[0]
    nd, cols = cfg[C_ND], cfg[C_COLS]
    stride = run_stride(nd)
    vbase = lbuf.shape[0] - 18 * cols * stride  # per chain three row slots of three paths
    hb = t * area_runs(cols) * stride
    top = (h + 1) // 2
    where, masks, caller = spread
    state = 0 if workers > 1 else STAY
    for n in range(2 if workers <= 2 else 1):
        c = (t + n) & 1
        rows = top if c == 0 else h - top
        if n == 1:
            store_release(nxt, (5 + c) * NXT_STRIDE, 1)
        while n == 1 or load_acquire(nxt, (5 + c) * NXT_STRIDE) == 0:
            j = fetch_add(nxt, c * NXT_STRIDE, 2)
            if j >= rows:
                break
            n2 = min(2, rows - j)
            if state == 0:
                state = spread_out(t, workers, caller, where, masks[t])
            _chain_rows(c, j, n2, hb, vbase + c * 9 * cols * stride, img, right, cl, crr, cfg,
                        p2tab, prog, disp, win, offs, cost, lbuf, mv[c], pm, acc, rmin,
                        rarg, karg, BAND if workers > 1 else cols)
            if fetch_add(nxt, (2 + c) * NXT_STRIDE, n2) + n2 == rows and cfg[C_SPW] > 0:
                _speckle_half(c, top, cfg, nxt, disp, spk)


@nb.njit(**_JIT)
def _speckle_half(c: int, top: int, cfg: np.ndarray, nxt: np.ndarray, disp: np.ndarray,
                  spk: tuple) -> None:
    """The speckle filter's part for half c, run by the worker that finished its last row:
    its regions (postfilter.label_band); the second half to get here also joins the regions
    across the seam and clears the small joined ones. Nobody waits for the other half."""
    labels, stack, size, parent, rtype = spk
    h = disp.shape[0]
    inv, spw, spr = cfg[C_INV], cfg[C_SPW], cfg[C_SPR]
    halves = 2 if h > top else 1
    r0, r1 = (0, top) if c == 0 else (top, h)
    edge = top - 1 if c == 0 and halves == 2 else top if c == 1 else -1
    label_band(disp, r0, r1, edge, inv, spw, spr, labels, stack, size, parent, rtype)
    if fetch_add(nxt, 4 * NXT_STRIDE, 1) == 1:
        join_seam(disp, top, inv, spr, labels, size, parent)
        clear_seam(disp, top, inv, spw, labels, stack, size, parent)


@nb.njit(parallel=True, **_JIT)
def sgm_single_pass(img: np.ndarray, right: np.ndarray, cl: np.ndarray, crr: np.ndarray,
                    cfg: np.ndarray, p2tab: np.ndarray, nxt: np.ndarray, prog: np.ndarray,
                    disp: np.ndarray, win: tuple, offs: np.ndarray,
                    cost: np.ndarray, lbuf: np.ndarray, mv: np.ndarray,
                    pm: np.ndarray, acc: np.ndarray, rmin: np.ndarray, rarg: np.ndarray,
                    karg: np.ndarray, spk: tuple, workers: int, spread: tuple) -> None:
    """Disparity map of the pair (img left, right) with five paths in one pass per half,
    each row's census codes (into cl, crr) made on the way and the speckle filter run per
    half (spk: its scratch labels, stack, size, parent, rtype, as postfilter.label_band): the
    two horizontal ones, and from above (top half, rows < ceil(h / 2)) or from below (the
    rest) the vertical and both diagonals. The halves are independent chains, one per
    worker; more workers share them two rows at a time (_single_pass). Scratch has
    one slice per worker (leading axis, at least ``workers``; win: census_row_pair's raw,
    smooth and key, keys -1); nxt and prog must be zero; spread: cpus.spread_out's where
    (all -1), per-worker masks and the calling thread's threading.get_ident()."""
    for t in nb.prange(workers):
        _single_pass(t, img, right, cl, crr, cfg, p2tab, nxt, prog, disp,
                     (win[0][t], win[1][t], win[2][t]), offs,
                     cost[t], lbuf[0], mv, pm[t], acc[t], rmin[t], rarg[t],
                     karg[t], spk, workers, spread)
    restore(spread[0], spread[1], workers)
