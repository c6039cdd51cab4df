"""Small synthetic pairs with exact sub-pixel truth for the SGM bench and tests: a textured
plane, slanted and optionally curved, seen with a gain difference between the eyes."""
from __future__ import annotations

import numpy as np


def slanted_plane(h: int, w: int, d0: float, slope: float, seed: int, curve: float = 0.0,
                  gain: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(left, right, truth) uint8, uint8, float32: truth d(x, y) = d0 + slope * x
    + curve * 20 * ((y - h/2) / h)**2 px; the left image samples the right eye's texture at
    x - d(x, y) (bicubic), times gain. The texture is blurred noise (sigma 1.2 px)."""
    import cv2

    rng = np.random.default_rng(seed)
    margin = int(np.ceil(max(abs(d0), abs(d0 + slope * w)) + 20 * abs(curve))) + 8
    tex = cv2.GaussianBlur(rng.uniform(0, 255, (h, w + 2 * margin)).astype(np.float32), (0, 0),
                           1.2)
    tex = (tex - tex.mean()) * 3 + 128
    xs = np.arange(w, dtype=np.float32)[None, :]
    ys = np.arange(h, dtype=np.float32)[:, None]
    gt = (d0 + slope * xs + curve * 20 * ((ys - h / 2) / h) ** 2).astype(np.float32)
    gt = np.broadcast_to(gt, (h, w)).astype(np.float32)
    mapx = (xs + margin - gt).astype(np.float32)
    mapy = np.broadcast_to(ys, (h, w)).astype(np.float32)
    left = cv2.remap(tex, mapx, mapy, cv2.INTER_CUBIC) * gain
    right = tex[:, margin:margin + w]
    return (np.clip(left, 0, 255).astype(np.uint8), np.clip(right, 0, 255).astype(np.uint8), gt)


def fraction_bias(disp16: np.ndarray, gt: np.ndarray, invalid: int,
                  bins: int = 5) -> tuple[np.ndarray, float]:
    """Mean error (px) of valid estimates per bin of the truth's offset from the nearest whole
    pixel (-0.5 .. 0.5), and their RMS error. Pixel locking shows as positive bias in the low
    bins and negative in the high ones."""
    ok = (disp16 != invalid) & np.isfinite(gt)
    err = disp16[ok].astype(np.float64) / 16 - gt[ok]
    frac = gt[ok] - np.floor(gt[ok] + 0.5)
    idx = np.minimum(((frac + 0.5) * bins).astype(int), bins - 1)
    bias = np.array([err[idx == i].mean() if np.any(idx == i) else np.nan for i in range(bins)])
    return bias, float(np.sqrt(np.mean(err ** 2)))
