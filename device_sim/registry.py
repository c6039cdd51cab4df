"""The simulators alive in this process, so ``sim://?serial=SN`` and ``stereocam.list_devices`` find them."""
from __future__ import annotations

import threading
import weakref
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .firmware import SimulatedCamera

_live: "weakref.WeakSet[SimulatedCamera]" = weakref.WeakSet()
_lock = threading.Lock()


def register(sim: "SimulatedCamera") -> None:
    with _lock:
        _live.add(sim)


def unregister(sim: "SimulatedCamera") -> None:
    with _lock:
        _live.discard(sim)


def live_simulators() -> list["SimulatedCamera"]:
    """Open (not closed) simulators of this process, attached to a link or not."""
    with _lock:
        return sorted(_live, key=lambda s: s.serial)


def find_free(serial: str) -> "SimulatedCamera | None":
    """A live simulator with this serial that no link holds."""
    return next((s for s in live_simulators() if s.serial == serial and not s.attached), None)
