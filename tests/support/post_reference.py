"""Plain numpy post-processing (SPEC §5.3): the specification stereocam.stereo.post is bit-exact with.

Written for reading, not speed. Disparities are int16 codes (disparity * DISPARITY_SUBPIXEL); the
invalid code is the protocol's invalid_disparity(min_disparity). Stages, in chain order:

1. lr_check (t >= 0): left pixel x with disparity d survives when the right view's disparity R at
   xr = x - floor((d + S/2) / S) (S = DISPARITY_SUBPIXEL) exists (0 <= xr < w), is valid and
   |R - d| <= t * S.
2. hole_fill 1 (nearest): an invalid pixel takes the nearest valid pixel of its row; on a tie the
   smaller. hole_fill 2 (background): the first valid pixel along each of the 8 paths from the
   pixel outwards; the second smallest of those found, or the only one.
3. spatial (alpha a > 0, delta t, n iterations): n times: every row left to right then right to
   left, then every column top to bottom then bottom to top; along a sweep, a valid pixel c whose
   already-filtered predecessor p is valid with |c - p| <= t becomes floor((a c + (256 - a) p + 128) / 256).
4. temporal (alpha a > 0, delta t, persistence k): with last = the previous output and history =
   the validity of the previous frames (bit i: i + 1 frames ago): valid c with valid last p within t
   blends as in 3; invalid c takes p if p is valid and a bit of history & (2^k - 1) is set. The first
   frame passes through.
5. median (3 or 5): the median of each window, the edge replicated, invalid codes included.
6. decimation n > 1: each n x n block from the top left takes the lower median (sorted[(k - 1) // 2])
   of its k valid pixels, or invalid.
"""
from __future__ import annotations

import numpy as np

from stereocam.protocol.frame_messages import DISPARITY_SUBPIXEL as S

PATHS8 = [(0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1)]


def lr_check(disp: np.ndarray, right: np.ndarray, tol: int, invalid: int) -> np.ndarray:
    h, w = disp.shape
    d = disp.astype(np.int64)
    xr = np.arange(w)[None, :] - (d + S // 2) // S
    inside = (xr >= 0) & (xr < w)
    r = np.take_along_axis(right.astype(np.int64), np.clip(xr, 0, w - 1), axis=1)
    ok = inside & (r != invalid) & (np.abs(r - d) <= tol * S)
    return np.where((disp != invalid) & ~ok, invalid, disp).astype(np.int16)


def fill_nearest(disp: np.ndarray, invalid: int) -> np.ndarray:
    out = disp.copy()
    for y in range(disp.shape[0]):
        valid = np.flatnonzero(disp[y] != invalid)
        if valid.size == 0:
            continue
        for x in np.flatnonzero(disp[y] == invalid):
            dist = np.abs(valid - x)
            near = valid[dist == dist.min()]
            out[y, x] = disp[y, near].min()
    return out


def fill_background(disp: np.ndarray, invalid: int) -> np.ndarray:
    h, w = disp.shape
    out = disp.copy()
    for y, x in np.argwhere(disp == invalid):
        found = []
        for dy, dx in PATHS8:
            py, px = y + dy, x + dx
            while 0 <= py < h and 0 <= px < w and disp[py, px] == invalid:
                py, px = py + dy, px + dx
            if 0 <= py < h and 0 <= px < w:
                found.append(int(disp[py, px]))
        if found:
            out[y, x] = sorted(found)[min(len(found), 2) - 1]
    return out


def _blend(c: np.ndarray, p: np.ndarray, a: int) -> np.ndarray:
    return (a * c + (256 - a) * p + 128) // 256


def _sweep(lines: np.ndarray, alpha: int, delta: int, invalid: int) -> None:
    """In place along axis 1 of ``lines`` (int64), every line at once."""
    for i in range(1, lines.shape[1]):
        c, p = lines[:, i], lines[:, i - 1]
        ok = (c != invalid) & (p != invalid) & (np.abs(c - p) <= delta)
        lines[:, i] = np.where(ok, _blend(c, p, alpha), c)


def spatial(disp: np.ndarray, alpha: int, delta: int, iterations: int, invalid: int) -> np.ndarray:
    d = disp.astype(np.int64)
    for _ in range(iterations):
        _sweep(d, alpha, delta, invalid)
        _sweep(d[:, ::-1], alpha, delta, invalid)
        _sweep(d.T, alpha, delta, invalid)
        _sweep(d.T[:, ::-1], alpha, delta, invalid)
    return d.astype(np.int16)


def temporal(frames: list[np.ndarray], alpha: int, delta: int, persistence: int, invalid: int) -> list[np.ndarray]:
    """The outputs of a sequence of frames."""
    outs = [frames[0].copy()]
    last = frames[0].astype(np.int64)
    history = (frames[0] != invalid).astype(np.int64)
    for f in frames[1:]:
        c = f.astype(np.int64)
        valid, pvalid = c != invalid, last != invalid
        blend = valid & pvalid & (np.abs(c - last) <= delta)
        hold = ~valid & pvalid & ((history & ((1 << persistence) - 1)) != 0)
        out = np.where(blend, _blend(c, last, alpha), np.where(hold, last, c))
        history = ((history << 1) | valid) & 0xFF
        last = out
        outs.append(out.astype(np.int16))
    return outs


def median(disp: np.ndarray, size: int) -> np.ndarray:
    r = size // 2
    win = np.lib.stride_tricks.sliding_window_view(np.pad(disp, r, mode="edge"), (size, size))
    return np.sort(win.reshape(*disp.shape, -1), axis=-1)[..., size * size // 2].astype(np.int16)


def decimate(disp: np.ndarray, n: int, invalid: int) -> np.ndarray:
    out = disp.copy()
    h, w = disp.shape
    for by in range(0, h, n):
        for bx in range(0, w, n):
            block = disp[by:by + n, bx:bx + n]
            vals = np.sort(block[block != invalid])
            out[by:by + n, bx:bx + n] = vals[(vals.size - 1) // 2] if vals.size else invalid
    return out


def chain(disp: np.ndarray, p, invalid: int, right: np.ndarray | None = None) -> np.ndarray:
    """One frame through every stage ``p`` (a PostParams) turns on, in order; the temporal filter's
    first frame passes unchanged."""
    out = disp.copy()
    if p.lr_check >= 0:
        out = lr_check(out, right, p.lr_check, invalid)
    if p.hole_fill:
        out = (fill_nearest if p.hole_fill == 1 else fill_background)(out, invalid)
    if p.spatial_alpha:
        out = spatial(out, p.spatial_alpha, p.spatial_delta, p.spatial_iterations, invalid)
    if p.median_size > 1:
        out = median(out, p.median_size)
    if p.decimation > 1:
        out = decimate(out, p.decimation, invalid)
    return out


def confidence(matched: np.ndarray, final: np.ndarray, invalid: int) -> np.ndarray:
    """SPEC §5.3's confidence plane: 0 where ``final`` is invalid, CONFIDENCE_FILLED where ``matched``
    (the map after the left-right check) is, else BASE + PER_NEIGHBOUR * (8-neighbours within 1 px)."""
    from stereocam.protocol.frame_messages import CONFIDENCE_BASE, CONFIDENCE_FILLED, CONFIDENCE_PER_NEIGHBOUR

    h, w = matched.shape
    m = np.pad(matched.astype(np.int64), 1, constant_values=invalid)
    c = matched.astype(np.int64)
    n = np.zeros((h, w), np.int64)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy or dx:
                v = m[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
                n += (v != invalid) & (np.abs(v - c) <= S)
    out = np.where(matched == invalid, CONFIDENCE_FILLED, CONFIDENCE_BASE + CONFIDENCE_PER_NEIGHBOUR * n)
    return np.where(final == invalid, 0, out).astype(np.uint8)
