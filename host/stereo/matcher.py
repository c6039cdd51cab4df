"""Reusable matcher: validates inputs, owns scratch buffers, runs the pipeline."""
from __future__ import annotations

import threading
from numbers import Integral

import numba as nb
import numpy as np

from . import sad as _sad
from .params import Geometry, MatchParams, geometry
from .postfilter import filter_speckles
from .prefilter import prefilter_pair

STRIPES_PER_THREAD = 4  # handed out dynamically: a preempted thread delays one short stripe


def check_pair(left: np.ndarray, right: np.ndarray) -> None:
    """Raise ValueError unless left/right are same-shape 2-D uint8 arrays."""
    for name, img in (("left", left), ("right", right)):
        if not isinstance(img, np.ndarray):
            raise ValueError(f"{name} image must be a numpy array, got {type(img).__name__}")
        if img.ndim != 2:
            hint = (": turn colour grey first, e.g. cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)"
                    if img.ndim == 3 and img.shape[2] in (3, 4) else "")
            raise ValueError(f"{name} image must be 2-D (grey), got shape {img.shape}{hint}")
        if img.dtype != np.uint8:
            hint = (": scale it to 8 bits first, e.g. (img >> 8).astype(np.uint8) for 16-bit data"
                    if img.dtype == np.uint16 else "")
            raise ValueError(f"{name} image must be uint8, got {img.dtype}{hint}")
    if left.shape != right.shape:
        raise ValueError(f"left and right images differ in shape: {left.shape} vs {right.shape}")


def _stripes(lo: int, hi: int, n: int) -> np.ndarray:
    n = max(1, min(n, hi - lo))
    return np.array([lo + (hi - lo) * k // n for k in range(n + 1)], dtype=np.int64)


def _aligned(shape: tuple[int, ...], dtype, align: int = 64) -> np.ndarray:
    """Uninitialised C-contiguous array whose data starts on an `align`-byte boundary."""
    n = int(np.prod(shape)) * np.dtype(dtype).itemsize
    raw = np.empty(n + align, np.uint8)
    off = (-raw.ctypes.data) % align
    return raw[off:off + n].view(dtype).reshape(shape)


def _contiguous(img: np.ndarray) -> np.ndarray:
    img = np.ascontiguousarray(img)
    return img if img.flags.writeable else img.copy()  # one compiled signature only


def frame_shape(shape: object) -> tuple[int, int]:
    """(height, width) of a matcher's frames, or ValueError unless ``shape`` is a pair of ints."""
    if not isinstance(shape, (tuple, list)) or len(shape) != 2 or any(
            isinstance(v, bool) or not isinstance(v, Integral) for v in shape):
        raise ValueError(f"shape must be (height, width), two ints, got {shape!r}")
    return int(shape[0]), int(shape[1])


def prepared_pair(left: np.ndarray, right: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """The pair as the kernels take it (checked, of the matcher's ``shape``, C-contiguous, writable)."""
    check_pair(left, right)
    if left.shape != shape:
        raise ValueError(f"image shape {left.shape} differs from the matcher's {shape}")
    return _contiguous(left), _contiguous(right)


class Matcher:
    """Block matcher for one (shape, params); scratch buffers live between frames.

    ``nstripes`` fixes the number of row stripes (default: STRIPES_PER_THREAD per numba
    thread); the output does not depend on it. Calls are serialised by a lock.
    """

    def __init__(self, shape: tuple[int, int], params: MatchParams = MatchParams(),
                 nstripes: int | None = None) -> None:
        if not isinstance(params, MatchParams):
            raise ValueError(f"params must be MatchParams, got {type(params).__name__}")
        params.validate()
        h, w = frame_shape(shape)
        if nstripes is not None and (isinstance(nstripes, bool) or not isinstance(nstripes, Integral)):
            raise ValueError(f"nstripes must be an int or None, got {nstripes!r}")
        self.params = params
        self.shape = (h, w)
        self.geom: Geometry = geometry(h, w, params)
        self._nstripes = nstripes
        self._lock = threading.Lock()
        self._alloc_fixed()
        self._threads = 0
        self._ensure_threads(nb.get_num_threads())

    def _alloc_fixed(self) -> None:
        p, g = self.params, self.geom
        h, w = self.shape
        r, nd = p.block_size // 2, p.num_disparities
        self.pl = _aligned((h, w), np.uint8)
        self.pr = _aligned((h, w), np.uint8)
        self.pf_vsum = np.empty((2, 2, w + p.pre_filter_size + 3), np.int64)
        # virtual columns c = -r .. width1-1+r: clamped left column and right base column
        c = np.arange(-r, g.width1 + r)
        self.lc = (g.lofs + np.clip(c, -g.lofs, w - 1 - g.lofs)).astype(np.int64)
        self.rb = (g.rofs + np.clip(c, -g.rofs, w - nd - g.rofs)).astype(np.int64)
        self.acc = np.int16 if p.max_sad <= 32767 else np.int32
        self.big = self.acc(np.iinfo(self.acc).max)
        cfg = np.zeros(_sad.C_LEN, np.int64)
        cfg[[_sad.C_R, _sad.C_CAP, _sad.C_ND, _sad.C_MIND, _sad.C_TEX, _sad.C_URATIO,
             _sad.C_MAXDIFF, _sad.C_LOFS, _sad.C_WIDTH1, _sad.C_ROIX0, _sad.C_ROIX1,
             _sad.C_LRX0, _sad.C_LRX1, _sad.C_INV]] = [
            r, p.pre_filter_cap, nd, p.min_disparity, p.texture_threshold, p.uniqueness_ratio,
            p.disp12_max_diff, g.lofs, g.width1, g.roi_x0, g.roi_x1, g.lr_x0, g.lr_x1, p.invalid_value]
        self.cfg = cfg
        if p.use_speckle:
            self.labels = np.empty((h, w), np.int32)
            self.stack = np.empty((h * w, 2), np.int32)
            self.rtype = np.zeros(h * w + 1, np.uint8)
            self.size = np.empty(h * w + 1, np.int32)  # region sizes and roots (postfilter)
            self.parent = np.empty(h * w + 1, np.int32)

    def _ensure_threads(self, nthreads: int) -> None:
        """Per-thread scratch for every thread numba may run (sized once) and the stripe
        split for the nthreads threads active now."""
        if nthreads == self._threads:
            return
        if self._threads == 0:
            g, nd = self.geom, self.params.num_disparities
            # numba.get_thread_id() < this; numba.config sets its NUMBA_* names at run time (no stub has them)
            n = max(1, nb.config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]
            ncols, wide = self.lc.shape[0], max(self.shape[1], g.lofs + g.width1)
            self.vs = _aligned((n, ncols, nd), self.acc)
            self.ts = np.empty((n, ncols), np.int32)
            self.sad = _aligned((n, nd), self.acc)
            self.pix = _aligned((n, 5, g.width1), np.int32)
            self.drow = np.empty((n, wide), np.int16)
            self.crow = np.empty((n, wide), np.int32)
            self.d2buf = np.empty((n, self.shape[1]), np.int32)
            self.d2cost = np.empty((n, self.shape[1]), np.int32)
        n = self._nstripes or STRIPES_PER_THREAD * max(1, nthreads)
        self.bounds = _stripes(self.geom.roi_y0, self.geom.roi_y1, n)
        self._threads = nthreads

    def scratch_bytes(self) -> int:
        """Bytes of scratch this matcher keeps between frames."""
        return sum(v.nbytes for v in vars(self).values() if isinstance(v, np.ndarray))

    def match(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Disparity map (int16, disparity * 16; invalid = (min_disparity - 1) * 16)."""
        left, right = prepared_pair(left, right, self.shape)
        p, g = self.params, self.geom
        inv = p.invalid_value
        disp = np.empty(self.shape, np.int16)
        with self._lock:
            prefilter_pair(left, right, self.pl, self.pr, p.pre_filter_type, p.pre_filter_size,
                           p.pre_filter_cap, self.pf_vsum)
            disp[:g.roi_y0] = inv
            disp[g.roi_y1:] = inv
            self.run_sad(disp)
            if p.use_speckle:
                filter_speckles(disp, inv, p.speckle_window_size, p.speckle_range,
                                self.labels, self.stack, self.size, self.parent, self.rtype)
        return disp

    def run_sad(self, disp: np.ndarray) -> None:
        """SAD / winner-take-all / left-right stage on the prefiltered pair (self.pl, self.pr)."""
        self._ensure_threads(nb.get_num_threads())
        chunk = nb.set_parallel_chunksize(1)
        try:
            _sad.match_rows(self.pl, self.pr, disp, self.bounds, self.cfg, self.lc, self.rb,
                            self.big, self.vs, self.ts, self.sad, self.pix, self.drow,
                            self.crow, self.d2buf, self.d2cost)
        finally:
            nb.set_parallel_chunksize(chunk)


def bm_warm_up() -> None:
    """Compile (or load from numba's disk cache) the block-matching kernels."""
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (40, 96), dtype=np.uint8)
    for kw in (dict(num_disparities=16, block_size=9, disp12_max_diff=1,
                    speckle_window_size=10, speckle_range=16),
               dict(num_disparities=16, block_size=25, pre_filter_type="normalized")):
        Matcher(img.shape, MatchParams(**kw)).match(img, np.roll(img, -3, axis=1))
