"""The printed texture every primitive samples: band-limited noise and its mip pyramid, packed for numba."""
from __future__ import annotations

import numpy as np


def make_texture(seed: int, size: int = 512, levels: int = 9) -> list[np.ndarray]:
    """A tileable band-limited noise texture (zero mean, unit std) and its 2x2 mip pyramid."""
    rng = np.random.default_rng(seed)
    spec = np.fft.fft2(rng.standard_normal((size, size)))
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(size), np.fft.fftfreq(size), indexing="ij"))
    spec *= np.where(f > 0, 1.0 / np.maximum(f, 1.0 / size) ** 0.8, 0.0)  # pinkish spectrum
    tex = np.real(np.fft.ifft2(spec))
    tex = ((tex - tex.mean()) / tex.std()).astype(np.float32)
    pyramid = [tex]
    while len(pyramid) < levels and pyramid[-1].shape[0] > 1:
        t = pyramid[-1]
        pyramid.append(0.25 * (t[0::2, 0::2] + t[1::2, 0::2] + t[0::2, 1::2] + t[1::2, 1::2]))
    return pyramid


def pack_pyramid(pyramid: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Flatten a pyramid for numba: (data, offsets); level k has side size >> k."""
    offsets = np.zeros(len(pyramid) + 1, np.int64)
    for k, lev in enumerate(pyramid):
        offsets[k + 1] = offsets[k] + lev.size
    return np.concatenate([lev.ravel() for lev in pyramid]), offsets
