"""Single-thread stage timings of the SGM kernel (for ``bench matching --algorithm sgm
--profile``): for 4 and 8 paths the cost rows, the path aggregation and the row selection,
each run over every row of both path groups, as sgm_rows runs them; for 5 paths, whose stages
run interleaved row by row, the chains' row loop cut after each stage (census, cost row and
kept path, the other four paths and their sum, selection), each stage's time the difference
of two cuts, and the speckle filter per half."""
from __future__ import annotations

import statistics
import time

import numba as nb
import numpy as np

from stereocam.stereo import sgm as _sgm
from stereocam.stereo import sgm_one_pass as _one
from stereocam.stereo.census import census_row_pair

STEREO_KERNELS_INLINED = True  # stereo/jit.py: these kernels inline the package's, so its
# digest keys their disk cache too (numba's own key, this file, kept a stale cost_run: a crash)

SINGLE_PASS_STAGES = ("census rows", "cost row + kept path", "four paths + sum",
                      "wta+uniq+subpix+lr")


@nb.njit(cache=True)
def _costs(cl, crr, cfg, cost):
    for _ in range(2):
        for y in range(cl.shape[0]):
            _sgm._cost_row(cl, crr, y, cfg[_sgm.C_X0], cfg[_sgm.C_MIND], cfg[_sgm.C_ND],
                           cfg[_sgm.C_COLS], cfg[_sgm.C_OUTC], cost)


@nb.njit(cache=True)
def _aggregate(img, cfg, p2tab, cost, lbuf, mv, pm, acc):
    h = img.shape[0]
    nd, cols = cfg[_sgm.C_ND], cfg[_sgm.C_COLS]
    npaths = 2 if cfg[_sgm.C_PATHS] == 4 else 4
    for g in range(2):
        for step in range(h):
            y = step if g == 0 else h - 1 - step
            _sgm._aggregate_row(g, y, step == 0, npaths, 0, 0, 3 * _sgm.run_stride(nd),
                                step & 1, 1 - (step & 1), 0, cols, img, cfg, p2tab, cost, lbuf,
                                mv, pm, acc)


@nb.njit(cache=True)
def _select(cfg, acc, parked, rmin, rarg, karg, disp):
    for y in range(disp.shape[0]):
        _sgm._finish_row(y, cfg, acc, parked[y], rmin, rarg, karg, disp[y])


@nb.njit(cache=True)
def _single_pass_upto(stages, img, right, cl, crr, cfg, p2tab, disp, win, offs, cost, lbuf,
                      mv, pm, acc, rmin, rarg, karg):
    """sgm_single_pass's rows on one worker (chain 0, then 1, two rows at a time as
    sgm_one_pass._chain_rows), only their first ``stages`` stages (SINGLE_PASS_STAGES)."""
    h = img.shape[0]
    nd, cols = cfg[_sgm.C_ND], cfg[_sgm.C_COLS]
    stride = _sgm.run_stride(nd)
    vbase = lbuf.shape[0] - 18 * cols * stride
    top = (h + 1) // 2
    for c in range(2):
        rows = top if c == 0 else h - top
        dy = 1 - 2 * c
        for j in range(0, rows, 2):
            n = min(2, rows - j)
            y0 = j if c == 0 else h - 1 - j
            for r in range(n):
                census_row_pair(img, right, y0 + r * dy, cfg[_sgm.C_CW], cfg[_sgm.C_CH],
                                cfg[_sgm.C_TL], cfg[_sgm.C_TR], win, offs, cl, crr)
            if stages > 1:
                _sgm._kept_rows(1 - c, y0, y0 + dy if n == 2 else -1, 0, img, cl, crr, cfg,
                                p2tab, cost, lbuf)
            for r in range(n):
                jr, y = j + r, y0 + r * dy
                if stages > 2:
                    _sgm._aggregate_row(c, y, jr == 0, 5, 0, (3 + r * cols) * stride,
                                        vbase + c * 9 * cols * stride, jr % 3, (jr + 2) % 3, 0,
                                        cols, img, cfg, p2tab,
                                        cost[r * cols * nd:(r + 1) * cols * nd], lbuf, mv[c],
                                        pm, acc)
                if stages > 3:
                    _sgm._finish_row(y, cfg, acc, None, rmin, rarg, karg, disp[y])


@nb.njit(cache=True)
def _speckle_halves(cfg, disp, spk):
    nxt = np.zeros(_one.NXT_SLOTS * _one.NXT_STRIDE, np.int32)
    top = (disp.shape[0] + 1) // 2
    for c in range(2 if disp.shape[0] > top else 1):
        _one._speckle_half(c, top, cfg, nxt, disp, spk)


def cpu_ms(fn, repeat: int) -> float:
    """Median CPU ms (process time) of fn() on one thread, numba's and OpenCV's."""
    import cv2
    threads = nb.get_num_threads(), cv2.getNumThreads()
    nb.set_num_threads(1)
    cv2.setNumThreads(1)
    try:
        fn()
        ts = []
        for _ in range(repeat):
            t0 = time.process_time()
            fn()
            ts.append((time.process_time() - t0) * 1e3)
        return statistics.median(ts)
    finally:
        nb.set_num_threads(threads[0])
        cv2.setNumThreads(threads[1])


def cpu_ratios(base, fns, repeat: int) -> tuple[float, list[list[float]]]:
    """One thread, interleaved rounds (base, then each of fns, per round; one warm-up round):
    base's median CPU ms and each fn's per-round ratios of CPU time to base's. Interleaving
    keeps a machine whose speed drifts between minutes (a shared host) from skewing ratios."""
    import cv2
    threads = nb.get_num_threads(), cv2.getNumThreads()
    nb.set_num_threads(1)
    cv2.setNumThreads(1)
    try:
        times: list[list[float]] = [[] for _ in range(len(fns) + 1)]
        for r in range(repeat + 1):
            for ts, fn in zip(times, (base, *fns)):
                t0 = time.process_time()
                fn()
                if r:
                    ts.append(time.process_time() - t0)
        return (statistics.median(times[0]) * 1e3,
                [[t / t0 for t, t0 in zip(ts, times[0])] for ts in times[1:]])
    finally:
        nb.set_num_threads(threads[0])
        cv2.setNumThreads(threads[1])


def stage_ms(m, left: np.ndarray, right: np.ndarray, repeat: int) -> dict[str, float]:
    """Median CPU ms (process time, robust to a busy machine) per stage of SGMMatcher m, after
    one m.match so that its buffers hold a frame."""
    if m.params.paths == 5:
        return single_pass_stage_ms(m, left, right, repeat)
    disp = np.empty(m.shape, np.int16)
    acc = m.acc[0].copy()
    stages = {
        "cost rows": lambda: _costs(m.cl, m.crr, m.cfg, m.cost[0]),
        "path aggregation": lambda: _aggregate(left, m.cfg, m.p2tab, m.cost[0], m.lbuf[0],
                                               m.mv[0], m.pm[0], m.acc[0]),
        "sum+wta+uniq+subpix+lr": lambda: _select(m.cfg, acc, m.parked, m.rmin[0], m.rarg[0],
                                                  m.karg[0], disp),
    }
    return {name: cpu_ms(fn, repeat) for name, fn in stages.items()}


def single_pass_rows(m, left: np.ndarray, right: np.ndarray, stages: int,
                     out: np.ndarray) -> None:
    """SGMMatcher m's 5-path row loop on one worker with the census margins its last match
    set, cut after the first ``stages`` of SINGLE_PASS_STAGES; with all of them out holds the
    disparity map before the speckle filter."""
    m.skey[:] = -1
    _single_pass_upto(stages, left, right, m.cl, m.crr, m.cfg, m.p2tab, out,
                      (m.win[0], m.swin[0], m.skey[0]), m.census_offs, m.cost[0], m.lbuf[0],
                      m.mv, m.pm[0], m.acc[0], m.rmin[0], m.rarg[0], m.karg[0])


def speckle_halves(m, disp: np.ndarray) -> None:
    """The speckle filter of SGMMatcher m (5 paths) on disp, half by half as its workers run it."""
    _speckle_halves(m.cfg, disp, (m.labels, m.stack, m.size, m.parent, m.rtype))


def single_pass_stage_ms(m, left: np.ndarray, right: np.ndarray,
                         repeat: int) -> dict[str, float]:
    """stage_ms for 5 paths: cumulative cuts of the row loop, differenced; then the speckle
    filter over the rows' output and what m.match spends beyond the stages (census margins,
    dispatch, parallel region)."""
    m.match(left, right)
    rows = np.empty(m.shape, np.int16)
    cuts = [cpu_ms(lambda k=k: single_pass_rows(m, left, right, k, rows), repeat)
            for k in range(1, len(SINGLE_PASS_STAGES) + 1)]
    out = {name: t - (cuts[i - 1] if i else 0.0)
           for i, (name, t) in enumerate(zip(SINGLE_PASS_STAGES, cuts))}
    if m.params.use_speckle:
        scratch = np.empty_like(rows)

        def speckle():
            scratch[:] = rows
            speckle_halves(m, scratch)
        out["speckle (halves)"] = cpu_ms(speckle, repeat)
    out["rest of match"] = cpu_ms(lambda: m.match(left, right), repeat) - sum(out.values())
    return out
