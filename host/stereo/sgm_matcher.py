"""Reusable semi-global matcher: validates inputs, owns scratch buffers, runs the pipeline
census (census.py) -> aggregation and selection (sgm.py) -> speckle filter (postfilter.py); with 5
paths all three in one parallel region per frame (sgm_one_pass.sgm_single_pass)."""
from __future__ import annotations

import threading

import numba as nb
import numpy as np

from . import cpus
from . import sgm as _sgm
from . import sgm_one_pass as _one
from .census import census_offsets, census_pair, noise_margin
from .census_simd import FEW_PLANES, PLANES
from .matcher import STRIPES_PER_THREAD, _aligned, _stripes, frame_shape, prepared_pair
from .postfilter import filter_speckles
from .sgm_params import SGMGeometry, SGMParams, sgm_geometry


class SGMMatcher:
    """Semi-global matcher for one (shape, params); scratch buffers live between frames.

    Runs on two threads (one per group of path directions, or with 5 paths one per half of
    the image) when numba has them; the output does not depend on the thread count. With 5
    paths on Linux, a numba pool thread that shares a CPU with the calling thread or the other
    worker moves off it for the frame (cpus.py; the calling thread never moves). Calls are
    serialised by a lock."""

    def __init__(self, shape: tuple[int, int], params: SGMParams = SGMParams()) -> None:
        if not isinstance(params, SGMParams):
            raise ValueError(f"params must be SGMParams, got {type(params).__name__}")
        params.validate()
        h, w = frame_shape(shape)
        self.params = params
        self.shape = (h, w)
        self.geom: SGMGeometry = sgm_geometry(h, w, params)
        self._lock = threading.Lock()
        self._alloc()

    def _alloc(self) -> None:
        p, g = self.params, self.geom
        h, w = self.shape
        nd, cols = p.num_disparities, g.cols
        n = max(1, nb.config.NUMBA_NUM_THREADS)  # numba.get_thread_id() < this
        padded = (h + p.census_height - 1, w + p.census_width - 1 + 64)  # + vector slack
        if p.paths == 5:  # per worker, the padded window of the row it makes codes for, and
            # with a census margin the smoothed rows' ring (census.census_row_pair)
            self.win = np.zeros((n, p.census_height, padded[1]), np.uint8)
            self.swin = np.zeros((n, 2, 2 * p.census_height, padded[1]), np.uint8)
            self.skey = np.full((n, p.census_height), -1, np.int64)
        else:
            self.padl = np.zeros(padded, np.uint8)
            self.padr = np.zeros(padded, np.uint8)
            self.spadl = np.zeros(padded, np.uint8)  # census margin: the smoothed pair
            self.spadr = np.zeros(padded, np.uint8)
        self.census_offs = census_offsets(p.census_width, p.census_height, p.census_sparse,
                                          padded[1])
        wc = (w + 63) & ~63  # census codes per row (census.census_pair)
        planes = FEW_PLANES if p.max_cost <= 8 * FEW_PLANES else PLANES  # (census_simd.cost_run)
        self.cl = np.empty((h, planes, wc), np.uint8)  # the left codes as byte planes (census_pair)
        # the right codes as byte planes (census.census_pair), + codes left of the image (unused)
        self.crr = np.zeros((h, planes, wc + nd), np.uint8)
        cfg = np.zeros(_sgm.C_LEN, np.int64)
        cfg[[_sgm.C_ND, _sgm.C_MIND, _sgm.C_P1, _sgm.C_URATIO, _sgm.C_LRDIFF, _sgm.C_X0,
             _sgm.C_COLS, _sgm.C_PATHS, _sgm.C_INV, _sgm.C_OUTC, _sgm.C_CW, _sgm.C_CH,
             _sgm.C_SPW, _sgm.C_SPR, _sgm.C_P1G]] = [
            nd, p.min_disparity, p.p1, p.uniqueness_ratio, p.lr_max_diff, g.x0, cols, p.paths,
            p.invalid_value, p.outside_cost, p.census_width, p.census_height,
            p.speckle_window_size if p.use_speckle else 0, p.speckle_range, p.p1_ground_step]
        self.cfg = np.concatenate([cfg, _sgm.sum_places(nd)])
        # effective P2 per intensity step dI (at 255 + dI, -255 <= dI <= 255), and (row 1) the
        # same times 0x01010101 as sgm_simd.pixel_paths takes it
        self.p2tab = np.full((2, 511), p.p2, np.int64)
        if p.p2_adapt > 0:
            a, step = p.p2_adapt, np.abs(np.arange(-255, 256))
            self.p2tab[0] = np.minimum(p.p2, np.maximum(p.p1, p.p2 * a // (a + step)))
        self.p2tab[1] = self.p2tab[0] * 0x01010101
        stride = _sgm.run_stride(nd)  # path-cost runs, each 64-aligned in a 64-aligned lbuf
        if p.paths == 5:  # one pass per half (sgm_one_pass.sgm_single_pass); per worker n
            self.locks = np.zeros(_one.NXT_SLOTS * _one.NXT_STRIDE, np.int32)  # sgm_one_pass.NXT_STRIDE's slots
            self.done = np.zeros(h, np.int32)  # columns each row has published
            # horizontal-path areas (sgm_one_pass.area_runs), then per chain three row slots
            # of three paths
            area = _one.area_runs(cols) * stride
            self.lbuf = _aligned((1, n * area + 18 * cols * stride), np.uint8)
            self.lbuf[:] = 0  # the zero runs (predecessor of a path's first pixel) included
            self.mv = np.empty((2, 3, 3, cols), np.uint32)
            # each worker's CPU (and thread id once moved), then the caller's CPU, and each
            # worker's CPU masks (cpus.spread_out, cpus.restore)
            self.where = np.full((n + 1) * cpus.WHERE_STRIDE, -1, np.int64)
            self.masks = np.zeros((n, 2, cpus.MASK_WORDS), np.uint64)
        else:  # two groups of paths (sgm.sgm_rows)
            n = 2
            self.parked = _aligned((h, cols * nd), np.int16)
            self.locks = np.zeros(h, np.int32)
            self.done = np.zeros(h, np.int32)
            self.lbuf = _aligned((2, 3 * stride + 6 * cols * stride), np.uint8)
            self.lbuf[:] = 0  # the zero run included
            self.mv = np.empty((2, 2, 3, cols), np.uint32)
        # per worker or group of paths: cost row (5 paths: two, sgm._kept_rows), uint8 path
        # buffers (sgm._aggregate_row) and their minima
        self.cost = _aligned((n, (2 if p.paths == 5 else 1) * cols * nd), np.uint8)
        # written at every pixel by every thread: each one's slice 128 bytes away from the
        # others' (path minima), never on one cache line (false sharing made two threads slower than one)
        self.pm = np.zeros((n, 64), np.uint32)  # 4 used
        self.acc = _aligned((n, cols * nd), np.int16)
        self.rmin = np.empty((n, cols + nd - 1), np.int16)
        self.rarg = np.zeros((n, cols + nd - 1), np.int16)
        self.karg = np.empty((n, 3, cols), np.int32)  # a row's winners, subpixel fractions
        m = h * w if p.use_speckle else 0
        self.labels = np.empty((h, w) if m else (0, 0), np.int32)
        self.stack = np.empty((m, 2), np.int32)
        self.rtype = np.zeros(m + 1, np.uint8)
        self.size = np.empty(m + 1, np.int32)  # region sizes and roots (postfilter)
        self.parent = np.empty(m + 1, np.int32)

    def scratch_bytes(self) -> int:
        """Bytes of scratch this matcher keeps between frames."""
        return sum(v.nbytes for v in vars(self).values() if isinstance(v, np.ndarray))

    def match(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Disparity map (int16, disparity * 16; invalid = (min_disparity - 1) * 16)."""
        left, right = prepared_pair(left, right, self.shape)
        p = self.params
        disp = np.empty(self.shape, np.int16)
        with self._lock:
            self.run_sgm(left, right, disp)
            if p.use_speckle and p.paths != 5:
                filter_speckles(disp, p.invalid_value, p.speckle_window_size, p.speckle_range,
                                self.labels, self.stack, self.size, self.parent, self.rtype)
        return disp

    def margins(self, left: np.ndarray, right: np.ndarray) -> tuple[int, int]:
        """The census margins of the left and right image (SGMParams.census_margin)."""
        m = self.params.census_margin
        return (noise_margin(left), noise_margin(right)) if m < 0 else (m, m)

    def run_census(self, left: np.ndarray, right: np.ndarray) -> None:
        """Census codes of the pair into self.cl and self.crr (mirrored rows), for 4 and 8
        paths (5 paths make them row by row in run_sgm)."""
        p = self.params
        tl, tr = self.margins(left, right)
        bounds = _stripes(0, self.padl.shape[0], STRIPES_PER_THREAD * nb.get_num_threads())
        chunk = nb.set_parallel_chunksize(1)
        try:
            census_pair(left, right, p.census_width, p.census_height, tl, tr, bounds, self.padl,
                        self.padr, self.spadl, self.spadr, self.census_offs, self.cl, self.crr)
        finally:
            nb.set_parallel_chunksize(chunk)

    def run_sgm(self, left: np.ndarray, right: np.ndarray, disp: np.ndarray) -> None:
        """Census, aggregation and selection (disp before the speckle filter; with 5 paths
        after it)."""
        if self.params.paths != 5:
            self.run_census(left, right)
        self.locks[:] = 0
        self.done[:] = 0
        chunk = nb.set_parallel_chunksize(1)
        try:
            if self.params.paths == 5:
                self.cfg[_sgm.C_TL], self.cfg[_sgm.C_TR] = self.margins(left, right)
                self.skey[:] = -1
                self.where[:] = -1
                cpus.note_cpu(self.where, nb.get_num_threads())
                _one.sgm_single_pass(left, right, self.cl, self.crr, self.cfg, self.p2tab,
                                     self.locks, self.done, disp,
                                     (self.win, self.swin, self.skey), self.census_offs,
                                     self.cost, self.lbuf, self.mv,
                                     self.pm, self.acc, self.rmin, self.rarg,
                                     self.karg, (self.labels, self.stack, self.size,
                                                  self.parent, self.rtype),
                                     nb.get_num_threads(),
                                     (self.where, self.masks, np.uint64(threading.get_ident())))
                return
            _sgm.sgm_rows(left, self.cl, self.crr, self.cfg, self.p2tab, self.parked, self.locks,
                          self.done, disp, self.cost, self.lbuf, self.mv, self.pm,
                          self.acc, self.rmin, self.rarg, self.karg)
        finally:
            nb.set_parallel_chunksize(chunk)


def sgm_warm_up() -> None:
    """Compile (or load from numba's disk cache) the SGM kernels: the 5-path one-pass kernel
    (the default) and the 4- and 8-path one (sgm_rows, census_pair and filter_speckles), so that
    a device configured for either does not compile on its first frame."""
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (24, 64), dtype=np.uint8)
    for paths in (5, 4):
        SGMMatcher(img.shape, SGMParams(num_disparities=16, paths=paths)).match(
            img, np.roll(img, -3, axis=1))
