"""Reusable matcher: validates inputs, owns scratch buffers, runs the pipeline."""
from __future__ import annotations

import threading

import numba as nb
import numpy as np

from .params import Geometry, MatchParams, geometry
from .postfilter import filter_speckles
from .prefilter import prefilter_pair
from .sad import match_rows


def check_pair(left: np.ndarray, right: np.ndarray) -> None:
    """Raise ValueError unless left/right are same-shape 2-D uint8 arrays."""
    for name, img in (("left", left), ("right", right)):
        if not isinstance(img, np.ndarray):
            raise ValueError(f"{name} image must be a numpy array, got {type(img).__name__}")
        if img.ndim != 2:
            raise ValueError(f"{name} image must be 2-D (grey), got shape {img.shape}")
        if img.dtype != np.uint8:
            raise ValueError(f"{name} image must be uint8, got {img.dtype}")
    if left.shape != right.shape:
        raise ValueError(f"left and right images differ in shape: {left.shape} vs {right.shape}")


STRIPES_PER_THREAD = 4


def _reciprocals(max_q: int) -> np.ndarray:
    """M[q] = ceil(2**40 / q): floor(a / q) == (a * M[q]) >> 40 for 0 <= a <= 2**22, q < 2**15."""
    q = np.arange(max_q + 1, dtype=np.int64)
    out = np.zeros(max_q + 1, np.int64)
    out[1:] = -((-(1 << 40)) // q[1:])
    return out


def _stripes(lo: int, hi: int, n: int) -> np.ndarray:
    n = max(1, min(n, hi - lo))
    return np.array([lo + (hi - lo) * k // n for k in range(n + 1)], dtype=np.int64)


class Matcher:
    """Block matcher for one (shape, params); scratch buffers live between frames."""

    def __init__(self, shape: tuple[int, int], params: MatchParams = MatchParams(),
                 nstripes: int | None = None) -> None:
        params.validate()
        h, w = int(shape[0]), int(shape[1])
        self.params = params
        self.shape = (h, w)
        self.geom: Geometry = geometry(h, w, params)
        self._nstripes = nstripes
        self._lock = threading.Lock()
        self._alloc()

    def _alloc(self) -> None:
        p, g = self.params, self.geom
        h, w = self.shape
        r, nd = p.block_size // 2, p.num_disparities
        self.pl = np.empty((h, w), np.uint8)
        self.pr = np.empty((h, w), np.uint8)
        self.pf_vsum = np.empty((2, w + p.pre_filter_size + 2), np.int32)
        # virtual columns c = -r .. width1-1+r: clamped left column and right base column
        c = np.arange(-r, g.width1 + r)
        self.lc = (g.lofs + np.clip(c, -g.lofs, w - 1 - g.lofs)).astype(np.int64)
        self.rb = (g.rofs + np.clip(c, -g.rofs, w - nd - g.rofs)).astype(np.int64)
        # a few stripes per thread, handed out dynamically: a descheduled thread then delays
        # the frame by one short stripe, not by half of it
        ns = self._nstripes or STRIPES_PER_THREAD * max(1, nb.get_num_threads())
        self.bounds = _stripes(g.roi_y0, g.roi_y1, ns)
        ns = self.bounds.shape[0] - 1
        acc = np.int16 if p.max_sad <= 32767 else np.int32
        ncols = self.lc.shape[0]
        wide = max(w, g.lofs + g.width1)
        self.vs = np.empty((ns, ncols, nd), acc)
        self.ts = np.empty((ns, ncols), np.int32)
        self.sad = np.empty((ns, nd), acc)
        self.big = acc(np.iinfo(acc).max)
        self.recip = _reciprocals(p.max_sad) if acc is np.int16 else np.zeros(0, np.int64)
        self.drow = np.empty((ns, wide), np.int16)
        self.crow = np.empty((ns, wide), np.int32)
        self.d2buf = np.empty((ns, w), np.int32)
        self.d2cost = np.empty((ns, w), np.int32)
        if p.use_speckle:
            self.labels = np.empty((h, w), np.int32)
            self.stack = np.empty((h * w, 2), np.int32)
            self.rtype = np.zeros(h * w + 1, np.uint8)

    def match(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Disparity map (int16, disparity * 16; invalid = (min_disparity - 1) * 16)."""
        check_pair(left, right)
        if left.shape != self.shape:
            raise ValueError(f"image shape {left.shape} differs from the matcher's {self.shape}")
        left = np.ascontiguousarray(left)
        right = np.ascontiguousarray(right)
        p, g = self.params, self.geom
        h, w = self.shape
        inv = p.invalid_value
        disp = np.empty((h, w), np.int16)
        with self._lock:
            prefilter_pair(left, right, self.pl, self.pr, p.pre_filter_type, p.pre_filter_size,
                           p.pre_filter_cap, self.pf_vsum)
            disp[:g.roi_y0] = inv
            disp[g.roi_y1:] = inv
            self.run_sad(disp)
            if p.use_speckle:
                filter_speckles(disp, inv, p.speckle_window_size, p.speckle_range,
                                self.labels, self.stack, self.rtype)
        return disp

    def run_sad(self, disp: np.ndarray) -> None:
        """SAD / winner-take-all / left-right stage on the prefiltered pair (self.pl, self.pr)."""
        p, g = self.params, self.geom
        chunk = nb.set_parallel_chunksize(1)
        try:
            match_rows(self.pl, self.pr, disp, self.bounds, p.block_size // 2,
                       p.pre_filter_cap, p.num_disparities, p.min_disparity,
                       p.texture_threshold, p.uniqueness_ratio, p.disp12_max_diff, g.lofs,
                       g.width1, g.roi_x0, g.roi_x1, g.lr_x0, g.lr_x1, self.lc, self.rb,
                       self.vs, self.ts, self.sad, self.big, self.recip, self.drow, self.crow,
                       self.d2buf, self.d2cost)
        finally:
            nb.set_parallel_chunksize(chunk)


_cache: dict[tuple, Matcher] = {}
_cache_lock = threading.Lock()


def match(left: np.ndarray, right: np.ndarray, params: MatchParams = MatchParams()) -> np.ndarray:
    """Match a rectified grey pair with a cached Matcher for (shape, params, threads)."""
    check_pair(left, right)
    if not isinstance(params, MatchParams):
        raise ValueError(f"params must be MatchParams, got {type(params).__name__}")
    key = (left.shape, params, nb.get_num_threads())
    with _cache_lock:
        m = _cache.get(key)
        if m is None:
            if len(_cache) >= 8:
                _cache.pop(next(iter(_cache)))
            m = _cache[key] = Matcher(left.shape, params)
    return m.match(left, right)
