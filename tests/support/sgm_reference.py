"""Plain numpy semi-global matching: the specification the numba engine is bit-exact with.

Every step is written for reading, not speed. Notation: the matched columns are X = x0 + x for
x in [0, cols) (sgm_geometry), disparity d = min_disparity + k for cost index k in [0, N).

1. census: per pixel one bit per window neighbour (width x height, centre excluded; with
   census_sparse only the neighbours (dy, dx) with |dx| + |dy| odd), in row order, set when
   the neighbour is darker than the centre; the image is extended by edge replication. With a
   margin t > 0 a bit is kept only where S, the image's 3x3 binomial smoothing ((sum + 8) >> 4,
   edges replicated), differs between neighbour and centre by more than t (also edge-replicated).
   t = census_margin, or with census_margin < 0 per image median |3x3 Laplacian| //
   MARGIN_DIVISOR (the lower median over the interior pixels of rows 1, 1 + LAPLACIAN_ROW_STEP,
   ...; 0 for images without interior pixels).
2. cost C[y, x, k] = popcount(census_L[y, X] ^ census_R[y, X - d]) (Hamming distance), or
   (3 * the number of census bits) // 8 where X - d < 0, left of the right image.
3. for each path direction r = (dy, dx): L_r(p) = C(p) where p - r leaves the matched
   rectangle, else L_r(p, k) = C(p, k) + min(L_r(q, k), L_r(q, k-1) + P1, L_r(q, k+1) + P1,
   m_q + P2') - m_q with q = p - r, m_q = min_k L_r(q, k) and P2' = P2, or with p2_adapt = a > 0
   P2' = min(P2, max(P1, P2 * a // (a + |I_L(p) - I_L(q)|))). On the vertical and diagonal
   paths, for p in rows y >= ceil(h / 2), the ground's step, a disparity growing downwards,
   costs P1g = p1_ground_step instead of P1: from L_r(q, k-1) walking down (dy = 1), from
   L_r(q, k+1) walking up (dy = -1).
   S = sum of the 4 (horizontal,
   vertical), 8 (plus diagonal) or 5 paths: the horizontal two and, in rows y < ceil(h / 2),
   the vertical and both diagonals from above, in the other rows those from below.
   (L <= census bits + P2 <= 255, as SGMParams demands.)
4. winner-take-all: k* = first argmin_k S; m = S[k*].
5. uniqueness (ratio u > 0): invalid when some k with |k - k*| > 1 has S[k] <= m + m * u // 100.
6. subpixel, equiangular (0 < k* < N-1, a = S[k*-1], b = S[k*+1]): den = max(max(a, b) - m, 1),
   out = 16 * (min_disparity + k*) + floor(((a - b) * 16 + den) / (2 * den)); else 16 * d.
   (Not the parabola's den = a + b - 2m, which pulls estimates toward whole pixels:
   tests/stereo/test_sgm_subpixel.py.)
7. left-right (lr_max_diff >= 0): the right image's winner for right column j is the first
   argmin over k of S at the left pixel x = j + k (same row); invalid when it differs from k*
   by more than lr_max_diff.
8. speckle filter: cv2.filterSpeckles(out, invalid, speckle_window_size, speckle_range).
"""
from __future__ import annotations

import cv2
import numpy as np

from stereocam.stereo.census import LAPLACIAN_ROW_STEP
from stereocam.stereo.sgm_params import MARGIN_DIVISOR, SGMParams, sgm_geometry

PATHS4 = [(0, 1), (0, -1), (1, 0), (-1, 0)]
PATHS8 = PATHS4 + [(1, 1), (1, -1), (-1, 1), (-1, -1)]
PATHS = {4: PATHS4, 8: PATHS8}
HALVES5 = (PATHS4[:3] + [(1, 1), (1, -1)],  # 5 paths, rows < ceil(h / 2): from above
           PATHS4[:2] + [(-1, 0), (-1, 1), (-1, -1)])  # the other rows: from below


def laplacian_median(img: np.ndarray) -> int:
    h, w = img.shape
    if h < 3 or w < 3:
        return 0
    i = img.astype(np.int64)
    lap = (i[:-2, :-2] - 2 * i[:-2, 1:-1] + i[:-2, 2:] - 2 * i[1:-1, :-2] + 4 * i[1:-1, 1:-1]
           - 2 * i[1:-1, 2:] + i[2:, :-2] - 2 * i[2:, 1:-1] + i[2:, 2:])
    lap = lap[::LAPLACIAN_ROW_STEP]
    return int(np.sort(np.abs(lap).ravel())[(lap.size - 1) // 2])


def margin(img: np.ndarray, p: SGMParams) -> int:
    return p.census_margin if p.census_margin >= 0 else laplacian_median(img) // MARGIN_DIVISOR


def smooth(img: np.ndarray) -> np.ndarray:
    k = np.array([1, 2, 1])
    padded = np.pad(img.astype(np.int64), 1, mode="edge")
    h, w = img.shape
    s = sum(k[a] * k[b] * padded[a:a + h, b:b + w] for a in range(3) for b in range(3))
    return ((s + 8) >> 4).astype(np.uint8)


def census(img: np.ndarray, width: int, height: int, t: int = 0, sparse: bool = False) -> np.ndarray:
    rx, ry = width // 2, height // 2
    h, w = img.shape
    padded = np.pad(img, ((ry, ry), (rx, rx)), mode="edge")
    sm = smooth(img).astype(np.int64)
    spadded = np.pad(sm, ((ry, ry), (rx, rx)), mode="edge")
    code = np.zeros((h, w), np.uint64)
    bit = 0
    for dy in range(-ry, ry + 1):
        for dx in range(-rx, rx + 1):
            if dy == 0 and dx == 0 or sparse and (abs(dx) + abs(dy)) % 2 == 0:
                continue
            neighbour = padded[ry + dy:ry + dy + h, rx + dx:rx + dx + w]
            on = neighbour < img
            if t > 0:
                on &= np.abs(spadded[ry + dy:ry + dy + h, rx + dx:rx + dx + w] - sm) > t
            code |= on.astype(np.uint64) << np.uint64(bit)
            bit += 1
    return code


def cost_volume(left: np.ndarray, right: np.ndarray, p: SGMParams) -> np.ndarray:
    g = sgm_geometry(*left.shape, p)
    cl = census(left, p.census_width, p.census_height, margin(left, p), p.census_sparse)
    cr = census(right, p.census_width, p.census_height, margin(right, p), p.census_sparse)
    cost = np.empty((g.height, g.cols, p.num_disparities), np.int32)
    xs = np.arange(g.x0, g.x1)
    for k in range(p.num_disparities):
        d = p.min_disparity + k
        inside = xs - d >= 0
        cost[:, :, k] = np.where(inside, np.bitwise_count(cl[:, xs] ^ cr[:, np.maximum(xs - d, 0)]),
                                 p.outside_cost)
    return cost


def _step(cost: np.ndarray, prev: np.ndarray, grad: np.ndarray, p: SGMParams, dy: int = 0) -> np.ndarray:
    """One path step for a batch of pixels: cost, prev (n, N); grad (n,) = |I(p) - I(q)|; dy:
    the direction of a ground step's path (0: none)."""
    big = np.iinfo(np.int32).max // 2
    m = prev.min(axis=1, keepdims=True)
    p2 = np.full(grad.shape, p.p2, np.int64)
    if p.p2_adapt > 0:
        p2 = np.minimum(p.p2, np.maximum(p.p1, p.p2 * p.p2_adapt // (p.p2_adapt + grad)))
    lower = np.pad(prev, ((0, 0), (1, 0)), constant_values=big)[:, :-1]  # L(q, k-1)
    upper = np.pad(prev, ((0, 0), (0, 1)), constant_values=big)[:, 1:]  # L(q, k+1)
    p1_lower = p.p1_ground_step if dy > 0 else p.p1  # the ground step walking down
    p1_upper = p.p1_ground_step if dy < 0 else p.p1  # and walking up
    best = np.minimum(np.minimum(prev, np.minimum(lower + p1_lower, upper + p1_upper)), m + p2[:, None])
    return cost + best - m


def aggregate_path(cost: np.ndarray, img: np.ndarray, dy: int, dx: int, p: SGMParams) -> np.ndarray:
    """L_r over the matched rectangle for r = (dy, dx); img is the left image's matched columns."""
    h, w, _ = cost.shape
    img = img.astype(np.int64)
    out = cost.copy()  # pixels whose predecessor is outside keep L = C
    if dy == 0:  # horizontal: columns in path order, all rows at once
        order = range(1, w) if dx > 0 else range(w - 2, -1, -1)
        for x in order:
            q = x - dx
            out[:, x] = _step(cost[:, x], out[:, q], np.abs(img[:, x] - img[:, q]), p)
        return out
    order = range(1, h) if dy > 0 else range(h - 2, -1, -1)
    top = (h + 1) // 2  # the ground step in rows from top only
    for y in order:
        xs = np.arange(w)
        inside = (xs - dx >= 0) & (xs - dx < w)
        x, q = xs[inside], xs[inside] - dx
        grad = np.abs(img[y, x] - img[y - dy, q])
        out[y, x] = _step(cost[y, x], out[y - dy, q], grad, p, dy if y >= top else 0)
    return out


def aggregate(left: np.ndarray, right: np.ndarray, p: SGMParams) -> np.ndarray:
    """S = sum over the paths of L_r, shape (height, cols, N), int32."""
    g = sgm_geometry(*left.shape, p)
    cost = cost_volume(left, right, p)
    img = left[:, g.x0:g.x1]
    if p.paths == 5:
        top = (g.height + 1) // 2
        upper, lower = (_path_sum(cost, img, paths, p) for paths in HALVES5)
        return np.concatenate([upper[:top], lower[top:]])
    return _path_sum(cost, img, PATHS[p.paths], p)


def _path_sum(cost: np.ndarray, img: np.ndarray, paths: list[tuple[int, int]],
              p: SGMParams) -> np.ndarray:
    path_costs = [aggregate_path(cost, img, dy, dx, p) for dy, dx in paths]
    assert max(L.max() for L in path_costs) <= 255  # the engine holds L in uint8
    return sum(path_costs)


def select(total: np.ndarray, p: SGMParams) -> np.ndarray:
    """Steps 4-7 on S (height, cols, N): disparity * 16 of the matched columns, or invalid."""
    h, w, nd = total.shape
    out = np.full((h, w), p.invalid_value, np.int64)
    xs, ks = np.arange(w), np.arange(nd)
    for y in range(h):
        s = total[y].astype(np.int64)
        k = s.argmin(axis=1)  # first minimum
        m = s[xs, k]
        ok = np.ones(w, bool)
        if p.uniqueness_ratio > 0:
            thr = m + m * p.uniqueness_ratio // 100
            others = np.abs(ks[None, :] - k[:, None]) > 1
            ok &= ~np.any((s <= thr[:, None]) & others, axis=1)
        if p.lr_max_diff >= 0:
            diag = np.full((w + nd - 1, nd), np.iinfo(np.int64).max)
            for kk in range(nd):  # right column j = x + N-1 - k (shifted to start at 0)
                diag[xs + nd - 1 - kk, kk] = s[:, kk]
            right_best = diag.argmin(axis=1)
            ok &= np.abs(right_best[xs + nd - 1 - k] - k) <= p.lr_max_diff
        inner = (k > 0) & (k < nd - 1)
        a = s[xs, np.clip(k - 1, 0, nd - 1)]
        b = s[xs, np.clip(k + 1, 0, nd - 1)]
        den = np.maximum(np.maximum(a, b) - m, 1)
        frac = np.where(inner, ((a - b) * 16 + den) // (2 * den), 0)
        out[y] = np.where(ok, 16 * (p.min_disparity + k) + frac, p.invalid_value)
    return out


def sgm(left: np.ndarray, right: np.ndarray, p: SGMParams) -> np.ndarray:
    """Disparity * 16 (int16), invalid = (min_disparity - 1) * 16."""
    g = sgm_geometry(*left.shape, p)
    disp = np.full(left.shape, p.invalid_value, np.int16)
    disp[:, g.x0:g.x1] = select(aggregate(left, right, p), p)
    if p.use_speckle:
        cv2.filterSpeckles(disp, p.invalid_value, p.speckle_window_size, p.speckle_range)
    return disp
