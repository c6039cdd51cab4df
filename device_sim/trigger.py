"""The external trigger line: one wire shared by several heads, pulsed by a master."""
from __future__ import annotations

import threading
from typing import Callable


class TriggerLine:
    """Every pulse reaches every head attached to the line with the same trigger id."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._heads: list[Callable[[int], None]] = []
        self.pulses = 0

    def attach(self, on_pulse: Callable[[int], None]) -> None:
        with self._lock:
            self._heads.append(on_pulse)

    def detach(self, on_pulse: Callable[[int], None]) -> None:
        with self._lock:
            if on_pulse in self._heads:
                self._heads.remove(on_pulse)

    def pulse(self) -> int:
        """Raise the line once; returns the trigger id the heads received."""
        with self._lock:
            self.pulses += 1
            tid = self.pulses
            heads = list(self._heads)
        for head in heads:
            head(tid)
        return tid
