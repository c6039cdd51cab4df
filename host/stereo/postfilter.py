"""Speckle filter with cv::filterSpeckles semantics (4-connected regions, in place)."""
from __future__ import annotations

import numba as nb
import numpy as np

_JIT = dict(nogil=True, cache=True, boundscheck=False)


@nb.njit(**_JIT)
def filter_speckles(img: np.ndarray, new_val: int, max_size: int, max_diff: int,
                    labels: np.ndarray, stack: np.ndarray, rtype: np.ndarray) -> None:
    """Set every 4-connected region of at most ``max_size`` pixels to ``new_val``.

    Neighbours join a region when neither is ``new_val`` and they differ by at most
    ``max_diff``. Scratch: labels int32 (h, w), stack int32 (h*w, 2), rtype uint8 (h*w + 1).
    """
    h, w = img.shape
    labels[:, :] = 0
    cur = 0
    for i in range(h):
        for j in range(w):
            if img[i, j] == new_val:
                continue
            lab = labels[i, j]
            if lab != 0:
                if rtype[lab] != 0:
                    img[i, j] = new_val
                continue
            cur += 1
            labels[i, j] = cur
            count = 0
            top = 0
            stack[0, 0] = i
            stack[0, 1] = j
            top = 1
            while top > 0:
                top -= 1
                py = stack[top, 0]
                px = stack[top, 1]
                count += 1
                dp = np.int32(img[py, px])
                if py < h - 1 and labels[py + 1, px] == 0:
                    q = np.int32(img[py + 1, px])
                    if q != new_val and abs(dp - q) <= max_diff:
                        labels[py + 1, px] = cur
                        stack[top, 0] = py + 1
                        stack[top, 1] = px
                        top += 1
                if py > 0 and labels[py - 1, px] == 0:
                    q = np.int32(img[py - 1, px])
                    if q != new_val and abs(dp - q) <= max_diff:
                        labels[py - 1, px] = cur
                        stack[top, 0] = py - 1
                        stack[top, 1] = px
                        top += 1
                if px < w - 1 and labels[py, px + 1] == 0:
                    q = np.int32(img[py, px + 1])
                    if q != new_val and abs(dp - q) <= max_diff:
                        labels[py, px + 1] = cur
                        stack[top, 0] = py
                        stack[top, 1] = px + 1
                        top += 1
                if px > 0 and labels[py, px - 1] == 0:
                    q = np.int32(img[py, px - 1])
                    if q != new_val and abs(dp - q) <= max_diff:
                        labels[py, px - 1] = cur
                        stack[top, 0] = py
                        stack[top, 1] = px - 1
                        top += 1
            if count <= max_size:
                rtype[cur] = 1
                img[i, j] = new_val
            else:
                rtype[cur] = 0



# The same filter in parts, for a matcher whose workers own row bands: each labels its band's
# regions and clears the small ones that do not reach its seam row (label_band); then one
# joins the regions across the seam (join_seam) and clears the small joined ones (clear_seam).
# Regions are connected components, so the result is filter_speckles' whatever the split.
# Scratch: labels int32 (h, w), stack int32 (h*w, 2), size and parent int32 (h*w + 1), rtype
# uint8 (h*w + 1); band r0 .. r1-1 numbers its regions from r0 * w + 1 and uses stack rows
# r0 * w .. r1 * w - 1.

@nb.njit(**_JIT)
def label_band(img: np.ndarray, r0: int, r1: int, edge: int, new_val: int, max_size: int,
               max_diff: int, labels: np.ndarray, stack: np.ndarray, size: np.ndarray,
               parent: np.ndarray, rtype: np.ndarray) -> None:
    """Label the regions of rows r0 .. r1-1 (labels 0 on ``new_val`` pixels; size[label]:
    pixels, parent[label] = label) and clear those of at most max_size pixels that have none
    on row ``edge`` (the seam; -1: none). Flat pixel indices (stack entries: index, column),
    a fifth faster than filter_speckles' row and column ones."""
    w = img.shape[1]
    im, lab, st = img.ravel(), labels.ravel(), stack.ravel()
    lo, hi = r0 * w, r1 * w  # the band's flat index range
    e0, e1 = edge * w, edge * w + w  # the seam row's
    lab[lo:hi] = 0
    cur = lo
    for o0 in range(lo, hi):
        if im[o0] == new_val:
            continue
        if lab[o0] != 0:
            if rtype[lab[o0]] != 0:
                im[o0] = new_val
            continue
        cur += 1
        lab[o0] = cur
        st[2 * lo] = o0
        st[2 * lo + 1] = o0 % w
        top = lo + 1
        count = 0
        seam = False
        while top > lo:
            top -= 1
            o = st[2 * top]
            px = st[2 * top + 1]
            count += 1
            seam |= e0 <= o < e1
            dp = np.int32(im[o])
            for k in range(4):  # below, above, right, left
                q = o + (w if k == 0 else -w if k == 1 else 1 if k == 2 else -1)
                inside = (q < hi if k == 0 else q >= lo if k == 1 else
                          px < w - 1 if k == 2 else px > 0)
                if inside and lab[q] == 0:
                    v = np.int32(im[q])
                    if v != new_val and abs(dp - v) <= max_diff:
                        lab[q] = cur
                        st[2 * top] = q
                        st[2 * top + 1] = px + (1 if k == 2 else -1 if k == 3 else 0)
                        top += 1
        size[cur] = count
        parent[cur] = cur
        rtype[cur] = count <= max_size and not seam
        if rtype[cur]:
            im[o0] = new_val


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
