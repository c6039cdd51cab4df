"""StereoBM prefilters (XSOBEL and NORMALIZED_RESPONSE), bit-exact with OpenCV.

Both map a uint8 image to uint8 values in [0, 2*cap], with ``cap`` meaning "zero response".
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .jit import KERNEL


@nb.njit(**KERNEL)
def _clip(v: int, cap: int) -> int:
    if v < -cap:
        return 0
    if v > cap:
        return 2 * cap
    return v + cap


@nb.njit(**KERNEL)
def _xsobel_pair_rows(src: np.ndarray, dst: np.ndarray, y: int, cap: int) -> None:
    """Output rows y and y+1 (y even): P = clip(d[y-1] + 2 d[y] + d[y+1]), d = I[x+1] - I[x-1]."""
    h, w = src.shape
    r0 = y - 1 if y > 0 else (y + 1 if h > 1 else y)
    r3 = y + 2 if y < h - 2 else y
    s0, s1, s2, s3 = src[r0], src[y], src[y + 1], src[r3]
    o0, o1 = dst[y], dst[y + 1]
    o0[0] = cap
    o0[w - 1] = cap
    o1[0] = cap
    o1[w - 1] = cap
    for x in range(1, w - 1):
        d0 = np.int32(s0[x + 1]) - np.int32(s0[x - 1])
        d1 = np.int32(s1[x + 1]) - np.int32(s1[x - 1])
        d2 = np.int32(s2[x + 1]) - np.int32(s2[x - 1])
        d3 = np.int32(s3[x + 1]) - np.int32(s3[x - 1])
        o0[x] = np.uint8(min(max(d0 + 2 * d1 + d2, -cap), cap) + cap)
        o1[x] = np.uint8(min(max(d1 + 2 * d2 + d3, -cap), cap) + cap)


@nb.njit(parallel=True, **KERNEL)
def xsobel_pair(left: np.ndarray, right: np.ndarray, dst_l: np.ndarray, dst_r: np.ndarray,
                cap: int) -> None:
    """XSOBEL on both images in one parallel region (rows in pairs, as OpenCV does them);
    an odd last row is all cap, as in OpenCV."""
    h = left.shape[0]
    npairs = h // 2
    for k in nb.prange(2 * npairs):
        if k < npairs:
            _xsobel_pair_rows(left, dst_l, 2 * k, cap)
        else:
            _xsobel_pair_rows(right, dst_r, 2 * (k - npairs), cap)
    if h % 2 == 1:
        dst_l[h - 1, :] = cap
        dst_r[h - 1, :] = cap


@nb.njit(**KERNEL)
def _normalized_rows(src: np.ndarray, dst: np.ndarray, winsize: int, cap: int,
                     buf: np.ndarray) -> None:
    """OpenCV prefilterNorm: vertical running box sums, horizontal box sum by prefix sums
    (the same integers as OpenCV's running sum), then the centre-weighted response."""
    h, w = src.shape
    r = winsize // 2
    scale_g = winsize * winsize // 8
    scale_s = (1024 + scale_g) // (scale_g * 2)
    scale_g *= scale_s
    vsum, cs = buf[0], buf[1]
    off = r + 1  # vsum[off + x] holds column x; pads of r + 1 on both sides
    n = w + 2 * off
    for x in range(w):
        vsum[off + x] = np.int64(src[0, x]) * (r + 2)
    for y in range(1, r):
        for x in range(w):
            vsum[off + x] += src[y, x]
    for y in range(h):
        top = src[max(y - r - 1, 0)]
        bottom = src[min(y + r, h - 1)]
        prev = src[max(y - 1, 0)]
        curr = src[y]
        nxt = src[min(y + 1, h - 1)]
        out = dst[y]
        for x in range(w):
            vsum[off + x] += np.int64(bottom[x]) - np.int64(top[x])
        for x in range(off):
            vsum[x] = vsum[off]
            vsum[off + w + x] = vsum[off + w - 1]
        cs[0] = 0
        for i in range(n):
            cs[i + 1] = cs[i] + vsum[i]
        # window sum of column x: cs[off + x + r + 1] - cs[off + x - r]
        c5 = (np.int64(curr[0]) * 5 + np.int64(curr[1]) + np.int64(prev[0])
              + np.int64(nxt[0]))
        sx = cs[off + r + 1] - cs[off - r]
        out[0] = np.uint8(_clip((c5 * scale_g - sx * scale_s) >> 10, cap))
        for x in range(1, w - 1):
            sx = cs[off + x + r + 1] - cs[off + x - r]
            c5 = (np.int64(curr[x]) * 4 + np.int64(curr[x - 1]) + np.int64(curr[x + 1])
                  + np.int64(prev[x]) + np.int64(nxt[x]))
            v = (c5 * scale_g - sx * scale_s) >> 10
            out[x] = np.uint8(min(max(v, -cap), cap) + cap)
        x = w - 1
        sx = cs[off + x + r + 1] - cs[off + x - r]
        c5 = (np.int64(curr[x]) * 5 + np.int64(curr[x - 1]) + np.int64(prev[x])
              + np.int64(nxt[x]))
        out[x] = np.uint8(_clip((c5 * scale_g - sx * scale_s) >> 10, cap))


@nb.njit(parallel=True, **KERNEL)
def normalized_pair(left: np.ndarray, right: np.ndarray, dst_l: np.ndarray,
                    dst_r: np.ndarray, winsize: int, cap: int, buf: np.ndarray) -> None:
    """NORMALIZED_RESPONSE on both images (one per thread).

    buf: int64 scratch of shape (2, 2, width + winsize + 3)."""
    for i in nb.prange(2):
        if i == 0:
            _normalized_rows(left, dst_l, winsize, cap, buf[0])
        else:
            _normalized_rows(right, dst_r, winsize, cap, buf[1])


def prefilter_pair(left: np.ndarray, right: np.ndarray, dst_l: np.ndarray, dst_r: np.ndarray,
                   kind: str, winsize: int, cap: int, buf: np.ndarray) -> None:
    """Apply the chosen prefilter to both images into dst_l / dst_r (buf: see normalized_pair)."""
    if kind == "xsobel":
        xsobel_pair(left, right, dst_l, dst_r, cap)
    else:
        normalized_pair(left, right, dst_l, dst_r, winsize, cap, buf)
