"""The device watchdog's own thread (SPEC §9): checked every ``PERIOD_S`` whatever the capture
thread is doing, so a sender blocked on a dead host never keeps a stream or a link alive."""
from __future__ import annotations

import logging
import threading
from typing import Callable

from .clock import REAL_CLOCK, Clock

PERIOD_S = 0.05
log = logging.getLogger(__name__)


class WatchdogThread:
    """Runs ``check`` every PERIOD_S of ``timebase`` until ``close``."""

    def __init__(self, check: Callable[[], None], name: str = "watchdog", timebase: Clock = REAL_CLOCK):
        self._check = check
        self._timebase = timebase
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._timebase.wait(self._stop, PERIOD_S):
            try:
                self._check()
            except Exception:  # a firmware bug must not end the watchdog: log and keep watching
                log.exception("watchdog check failed")

    def close(self) -> None:
        self._stop.set()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout=5)
