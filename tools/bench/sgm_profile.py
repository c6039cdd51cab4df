"""Single-thread stage timings of the SGM kernel (for ``bench matching --algorithm sgm
--profile``): the cost rows, the path aggregation and the row selection, each run over every
row of both path groups, as sgm_rows runs them (4 and 8 paths)."""
from __future__ import annotations

import statistics
import time

import numba as nb
import numpy as np

from stereocam.stereo import sgm as _sgm


@nb.njit(cache=True)
def _costs(cl, crr, cfg, cost):
    for _ in range(2):
        for y in range(cl.shape[0]):
            _sgm._cost_row(cl, crr, y, cfg[_sgm.C_X0], cfg[_sgm.C_MIND], cfg[_sgm.C_ND],
                           cfg[_sgm.C_COLS], cfg[_sgm.C_MAXC], cost)


@nb.njit(cache=True)
def _aggregate(img, cfg, p2tab, cost, lbuf, mv, pm, acc):
    h = img.shape[0]
    nd, cols = cfg[_sgm.C_ND], cfg[_sgm.C_COLS]
    npaths = 2 if cfg[_sgm.C_PATHS] == 4 else 4
    for g in range(2):
        for step in range(h):
            y = step if g == 0 else h - 1 - step
            _sgm._aggregate_row(g, y, step == 0, npaths, 0, 3 * (nd + 2), step & 1,
                                1 - (step & 1), 0, cols, img, cfg, p2tab, cost, lbuf, mv,
                                pm, acc)


@nb.njit(cache=True)
def _select(cfg, acc, parked, rmin, rarg, karg, disp):
    for y in range(disp.shape[0]):
        _sgm._finish_row(y, cfg, acc, parked[y], rmin, rarg, karg, disp[y])


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


def stage_ms(m, left: np.ndarray, repeat: int) -> dict[str, float]:
    """Median CPU ms (process time, robust to a busy machine) per stage of SGMMatcher m, after
    one m.match so that its buffers hold a frame; none for the single-pass 5 paths, whose
    stages run interleaved row by row."""
    if m.params.paths == 5:
        return {}
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
