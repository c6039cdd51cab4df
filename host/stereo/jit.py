"""The numba options the kernels are compiled with, typed so ``njit(**KERNEL)`` checks."""
from __future__ import annotations

from typing import Literal, TypedDict


class JitOptions(TypedDict, total=False):
    """The ``numba.njit`` keywords the kernels set."""

    nogil: bool
    cache: bool
    boundscheck: bool
    error_model: Literal["python", "numpy"]


KERNEL: JitOptions = {"nogil": True, "cache": True, "boundscheck": False}
"""Without the GIL (callers run kernels on threads), cached on disk, no bounds checks."""

C_ARITHMETIC: JitOptions = {**KERNEL, "error_model": "numpy"}
"""``KERNEL`` with C's integer division (no zero-division check), as the matching kernels need."""
