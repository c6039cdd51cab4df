"""Temporal filter with persistence (after librealsense's): a pixel valid now and close to its last
output blends towards it; one invalid now keeps its last output while it was valid in at least one
of the last ``persistence`` frames. The state lives in ``TemporalState``; the device resets it on a
configuration change or a trigger gap."""
from __future__ import annotations

from dataclasses import dataclass, field

import numba as nb
import numpy as np

from ..jit import KERNEL
from .spatial import _step


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
def _temporal_row(disp: np.ndarray, last: np.ndarray, history: np.ndarray, alpha: np.int32, delta: np.int32,
                  window: np.uint8, invalid: np.int32) -> None:
    """One row, branch-free (selects; the loop vectorises): a valid pixel steps towards its last
    output as the spatial filter's sweep does; an invalid one holds a valid last output while its
    history has a valid frame in the window."""
    for x in range(disp.shape[0]):
        cur, prev, past = np.int32(disp[x]), np.int32(last[x]), history[x]
        valid = cur != invalid
        hold = (prev != invalid) & ((past & window) != 0)
        out = _step(cur, prev, alpha, delta, invalid) if valid else (prev if hold else cur)
        history[x] = np.uint8((past << np.uint8(1)) | np.uint8(valid))
        disp[x] = out
        last[x] = out


@nb.njit(**KERNEL)
def _temporal(disp: np.ndarray, last: np.ndarray, history: np.ndarray, alpha: int, delta: int,
              persistence: int, invalid: int) -> None:
    window = np.uint8((1 << persistence) - 1)
    for y in range(disp.shape[0]):
        _temporal_row(disp[y], last[y], history[y], np.int32(alpha), np.int32(delta), window, np.int32(invalid))


def temporal_filter(disp: np.ndarray, state: TemporalState, alpha: int, delta: int, persistence: int,
                    invalid: int) -> None:
    """In place; the first frame (or one of another shape) only starts the state."""
    if state.last is None or state.history is None or state.last.shape != disp.shape:
        state.last = disp.copy()
        state.history = (disp != invalid).astype(np.uint8)
        return
    _temporal(disp, state.last, state.history, alpha, delta, persistence, invalid)
