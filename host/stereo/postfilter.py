"""Speckle filter with cv::filterSpeckles semantics (4-connected regions, in place).

Regions are found run by run: each row splits into runs of neighbours that join (neither is
``new_val``, they differ by at most ``max_diff``), and runs that touch on consecutive rows are
united (union-find over run ids, the root holding the region's size). A row's run starts, run
ends and joins with the row above are first flagged a register of pixels at a time; a row of
few runs then visits only the flagged pixels, one of many runs takes a branch-free pass per
pixel. The same filter runs in parts for a matcher whose workers own row bands: each labels its
band's regions and clears the small ones that do not reach its seam row (label_band); then one
joins the regions across the seam (join_seam) and clears the small joined ones (clear_seam). Regions are connected
components, so the result is filter_speckles' whatever the split.

Scratch: labels int32 (h, w) (a pixel's run id, 0 on ``new_val``); stack int32 (h*w, 2) (per
run id r: stack[r - 1] = flat index of its first pixel, length; clear_seam's flood stack);
size and parent int32 (h*w + 1); rtype uint8 (h*w + 1). Band r0 .. r1-1 numbers its runs from
r0 * w + 1.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .jit import KERNEL
from .lanes import ctz, popcount, uidx
from .postfilter_simd import run_flags

_JIT = KERNEL
RUNS_PER_PIXEL = 6  # _label_row: rows with more runs than w / this label pixel by pixel


@nb.njit(**_JIT)
def filter_speckles(img: np.ndarray, new_val: int, max_size: int, max_diff: int,
                    labels: np.ndarray, stack: np.ndarray, size: np.ndarray, parent: np.ndarray,
                    rtype: np.ndarray) -> None:
    """Set every 4-connected region of at most ``max_size`` pixels to ``new_val`` (the whole
    image as one band)."""
    label_band(img, 0, img.shape[0], -1, new_val, max_size, max_diff, labels, stack, size,
               parent, rtype)


@nb.njit(**_JIT)
def _row_flags(im: np.ndarray, o: int, a: int, w: int, new_val: int, max_diff: int,
               flags: np.ndarray) -> None:
    """flags[x] for the row at flat index o (the row above at a; a < 0: none): bit 0 a run
    starts at x, bit 1 one ends at x, bit 2 x joins the pixel above and is the first of its
    stretch of joins or a run start in either row (so each pair of runs side by side that
    join has at least one such x). A register at a time (postfilter_simd.run_flags), the
    first pixel and the tail one by one."""
    xv = 1
    if 0 <= max_diff <= 65535 and w > 2:
        xv = run_flags(im, o, a, 1, w - 1, new_val, max_diff, flags)
    flags[0] = _flags_at(im, o, a, 0, w, new_val, max_diff)
    for x in range(xv, w):
        flags[x] = _flags_at(im, o, a, x, w, new_val, max_diff)


@nb.njit(**_JIT)
def _flags_at(im: np.ndarray, o: int, a: int, x: int, w: int, nv: int, md: int) -> int:
    """_row_flags' flags of pixel x."""
    v = np.int64(im[o + x])
    p = np.int64(im[o + x - 1]) if x > 0 else nv
    n = np.int64(im[o + x + 1]) if x < w - 1 else nv
    s = v != nv and (p == nv or abs(v - p) > md)
    e = v != nv and (n == nv or abs(n - v) > md)
    k = False
    if a >= 0:
        u = np.int64(im[a + x])
        q = np.int64(im[a + x - 1]) if x > 0 else nv
        j = v != nv and u != nv and abs(v - u) <= md
        jp = p != nv and q != nv and abs(p - q) <= md
        su = u != nv and (q == nv or abs(u - q) > md)
        k = j and (not jp or s or su)
    return np.int64(s) | (np.int64(e) << 1) | (np.int64(k) << 2)


@nb.njit(**_JIT)
def _label_row(im: np.ndarray, lab: np.ndarray, st: np.ndarray, o: int, a: int, w: int,
               cur: int, new_val: int, max_diff: int, parent: np.ndarray, size: np.ndarray,
               flags: np.ndarray, dense: bool) -> tuple[int, bool]:
    """Runs of the row at flat index o (ids from cur + 1, each its own root until united,
    its pixels' labels and st slots written) united with those of the row above at a (a <
    0: none) where they join; returns the last id used and whether the row had many runs
    (more than one in RUNS_PER_PIXEL pixels). A row of few runs visits just the pixels where
    something happens (_row_flags' vector loops, then _label_row_events); one of many, where
    each visit's branches would cost more than a pass, takes the branch-free pass per pixel.
    dense: the previous row's answer, the guess for this one (so a map of short runs is not
    also flagged)."""
    if not dense:
        _row_flags(im, o, a, w, new_val, max_diff, flags)
        words = flags.view(np.uint64)
        runs = 0
        for i in range((w + 7) >> 3):
            runs += popcount(words[i] & np.uint64(0x0101010101010101))
        if runs * RUNS_PER_PIXEL <= w:
            return _label_row_events(im, lab, st, o, a, w, cur, parent, size, flags), False
    last = _label_row_pixels(im, lab, st, o, w, cur, new_val, max_diff, parent, size)
    if a >= 0:
        _unite_rows(im, lab, o, w, max_diff, parent, size)
    return last, (last - cur) * RUNS_PER_PIXEL > w


@nb.njit(**_JIT)
def _label_row_events(im: np.ndarray, lab: np.ndarray, st: np.ndarray, o: int, a: int, w: int,
                      cur: int, parent: np.ndarray, size: np.ndarray, flags: np.ndarray) -> int:
    """_label_row for a row of few runs: the flags (_row_flags) read eight at a time, each
    run start, join and run end handled where it is (labels written per run)."""
    words = flags.view(np.uint64)  # little-endian: flags[8 i + b] is byte b of words[i]
    start = done = 0  # the current run's first pixel; pixels labelled so far
    for i in range((w + 7) >> 3):
        word = words[i]
        while word != 0:
            t = np.int64(ctz(word)) & ~7
            x = 8 * i + (t >> 3)
            f = (word >> np.uint64(t)) & np.uint64(7)
            word &= ~(np.uint64(0xFF) << np.uint64(t))
            if f & 1:
                cur += 1
                start = x
                parent[cur] = cur
                size[cur] = 0
            if f & 4:
                _unite(parent, size, lab[a + x], cur)
            if f & 2:
                n = x - start + 1
                for z in range(o + done, o + start):
                    lab[z] = 0
                for z in range(o + start, o + x + 1):
                    lab[z] = cur
                done = x + 1
                st[2 * cur - 2] = o + start
                st[2 * cur - 1] = n
                size[cur if parent[cur] == cur else _root(parent, cur)] += n
    for z in range(o + done, o + w):
        lab[z] = 0
    return cur


@nb.njit(**_JIT)
def _label_row_pixels(im: np.ndarray, lab: np.ndarray, st: np.ndarray, o: int, w: int, cur: int,
                      new_val: int, max_diff: int, parent: np.ndarray, size: np.ndarray) -> int:
    """Runs of the row at flat index o (ids from cur + 1; each its own root, size its
    length); returns the last id used. Branch-free per pixel, for rows of many short runs: a
    pixel writes its flat index as the first pixel of run cur + 1 (final once that run starts
    here; the slot of an id not yet used otherwise) and as the last pixel of its own run (or
    of run cur + 1 if invalid); at most one run per pixel keeps both slots inside the band's
    ids."""
    first = cur + 1
    pv = np.int32(new_val)
    for x in range(w):
        i = uidx(o + x)
        v = np.int32(im[i])
        valid = v != new_val
        start = valid & ((pv == new_val) | (abs(v - pv) > max_diff))
        st[uidx(2 * cur)] = o + x
        cur += np.int64(start)
        lab[i] = cur if valid else 0
        st[uidx(2 * (cur + np.int64(not valid)) - 1)] = o + x
        pv = v
    for r in range(first, cur + 1):
        n = st[2 * r - 1] - st[2 * r - 2] + 1
        st[2 * r - 1] = n
        size[r] = n
        parent[r] = r
    return cur


@nb.njit(**_JIT)
def _unite_rows(im: np.ndarray, lab: np.ndarray, o: int, w: int, max_diff: int,
                parent: np.ndarray, size: np.ndarray) -> None:
    """Unite the runs of the row at flat index o with those of the row above where they join
    (once per pair of runs side by side)."""
    la = lb = 0
    for x in range(w):
        i, j = uidx(o + x), uidx(o - w + x)
        a, b = lab[j], lab[i]
        join = (a != 0) & (b != 0) & (abs(np.int32(im[i]) - np.int32(im[j])) <= max_diff)
        if join and (a != la or b != lb):
            la, lb = a, b
            _unite(parent, size, a, b)


@nb.njit(**_JIT)
def _unite(parent: np.ndarray, size: np.ndarray, a: int, b: int) -> None:
    """Join the regions of runs a and b: the larger root points to the smaller, which adds
    its size. No branch on whether they are one region already (unpredictable on maps of
    small regions): then the root points to itself and adds nothing."""
    ra, rb = _root(parent, a), _root(parent, b)
    lo, hi = min(ra, rb), max(ra, rb)
    grow = size[uidx(hi)] * np.int32(lo != hi)
    parent[uidx(hi)] = lo
    size[uidx(lo)] += grow


@nb.njit(**_JIT)
def label_band(img: np.ndarray, r0: int, r1: int, edge: int, new_val: int, max_size: int,
               max_diff: int, labels: np.ndarray, stack: np.ndarray, size: np.ndarray,
               parent: np.ndarray, rtype: np.ndarray) -> None:
    """Label the regions of rows r0 .. r1-1 (labels: run ids; _root(parent, id): the region's
    root, size[root]: its pixels) and clear those of at most max_size pixels that have none
    on row ``edge`` (the seam; none if outside the band)."""
    w = img.shape[1]
    im, lab, st = img.ravel(), labels.ravel(), stack.ravel()
    first = r0 * w + 1
    cur = r0 * w
    flags = np.zeros((w + 7) & ~7, np.uint8)  # _label_row's, whole words
    dense = False
    for y in range(r0, r1):
        cur, dense = _label_row(im, lab, st, y * w, (y - 1) * w if y > r0 else -1, w, cur,
                                new_val, max_diff, parent, size, flags, dense)
    rtype[first:cur + 1] = 0
    if r0 <= edge < r1:  # regions on the seam row wait for clear_seam
        for x in range(w):
            r = lab[edge * w + x]
            if r != 0:
                rtype[_root(parent, r)] = 1
    for r in range(first, cur + 1):
        root = _root(parent, r)
        if size[root] <= max_size and rtype[root] == 0:
            s = st[2 * r - 2]
            im[s:s + st[2 * r - 1]] = new_val


@nb.njit(**_JIT)
def _root(parent: np.ndarray, a: int) -> int:
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@nb.njit(**_JIT)
def join_seam(img: np.ndarray, y: int, new_val: int, max_diff: int, labels: np.ndarray,
              size: np.ndarray, parent: np.ndarray) -> None:
    """Join the regions of rows y - 1 and y (labelled in different bands) where they touch."""
    for x in range(img.shape[1]):
        a, b = np.int32(img[y - 1, x]), np.int32(img[y, x])
        if a == new_val or b == new_val or abs(a - b) > max_diff:
            continue
        ra, rb = _root(parent, labels[y - 1, x]), _root(parent, labels[y, x])
        if ra != rb:
            parent[rb] = ra
            size[ra] += size[rb]


@nb.njit(**_JIT)
def clear_seam(img: np.ndarray, y: int, new_val: int, max_size: int, labels: np.ndarray,
               stack: np.ndarray, size: np.ndarray, parent: np.ndarray) -> None:
    """After join_seam: clear the joined regions of at most max_size pixels that reach row
    y - 1 or y (each a flood fill over its own label's pixels; labels 0 once cleared)."""
    h, w = img.shape
    for r in range(max(y - 1, 0), min(y + 1, h)):
        for x in range(w):
            lab = labels[r, x]
            if lab == 0:
                continue
            root = _root(parent, lab)
            if size[root] > max_size:
                continue
            labels[r, x] = 0
            img[r, x] = new_val
            stack[0, 0] = r
            stack[0, 1] = x
            top = 1
            while top > 0:
                top -= 1
                py = stack[top, 0]
                px = stack[top, 1]
                for k in range(4):  # below, above, right, left
                    qy = py + (1 if k == 0 else -1 if k == 1 else 0)
                    qx = px + (1 if k == 2 else -1 if k == 3 else 0)
                    if 0 <= qy < h and 0 <= qx < w and labels[qy, qx] != 0 \
                            and _root(parent, labels[qy, qx]) == root:
                        labels[qy, qx] = 0
                        img[qy, qx] = new_val
                        stack[top, 0] = qy
                        stack[top, 1] = qx
                        top += 1
