"""Temporal filter with persistence (after librealsense's): a pixel valid now and close to its last
output blends towards it; one invalid now keeps its last output while it was valid in at least one
of the last ``persistence`` frames. The state lives in ``TemporalState``; the device resets it on a
configuration change or a trigger gap."""
from __future__ import annotations

from dataclasses import dataclass, field

import numba as nb
import numpy as np

from ..jit import KERNEL
from .spatial import _blend


@dataclass
class TemporalState:
    """The last output and the validity history (bit k: valid k + 1 frames ago) of every pixel."""

    last: np.ndarray | None = None  # int16, the previous frame's output
    history: np.ndarray | None = field(default=None)  # uint8

    def reset(self) -> None:
        """Forget the past: the next frame passes through unchanged."""
        self.last = None
        self.history = None


@nb.njit(**KERNEL)
def _temporal(disp: np.ndarray, last: np.ndarray, history: np.ndarray, alpha: int, delta: int,
              persistence: int, invalid: int) -> None:
    h, w = disp.shape
    window = (1 << persistence) - 1
    for y in range(h):
        for x in range(w):
            cur, prev = np.int32(disp[y, x]), np.int32(last[y, x])
            past = history[y, x]
            if cur != invalid:
                if prev != invalid and abs(cur - prev) <= delta:
                    disp[y, x] = _blend(cur, prev, alpha)
                history[y, x] = ((past << 1) | 1) & 0xFF
            else:
                if prev != invalid and past & window:
                    disp[y, x] = prev
                history[y, x] = (past << 1) & 0xFF
            last[y, x] = disp[y, x]


def temporal_filter(disp: np.ndarray, state: TemporalState, alpha: int, delta: int, persistence: int,
                    invalid: int) -> None:
    """In place; the first frame (or one of another shape) only starts the state."""
    if state.last is None or state.history is None or state.last.shape != disp.shape:
        state.last = disp.copy()
        state.history = (disp != invalid).astype(np.uint8)
        return
    _temporal(disp, state.last, state.history, alpha, delta, persistence, invalid)
