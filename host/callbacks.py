"""Frame callbacks (``Camera.on_frame``): a dispatcher listener whose own thread calls them, never
the link's reader; its queue drops the oldest frame when the callbacks fall behind.

A callback that raises is logged, counted and kept: ``FrameCallbacks.check()`` re-raises the first
such error as a CallbackError (its cause is the callback's exception). Nothing is swallowed, and
nothing a callback raises ends delivery: SystemExit and KeyboardInterrupt included (signals reach
only the main thread, so on this thread they come from the callback itself, and escaping would
only end this thread, not the program).
"""
from __future__ import annotations

import logging
import threading
from typing import Callable

from stereocam.protocol.errors import CallbackError

from .dispatch import DropPolicy, FrameQueue
from .frame_types import Frame

FrameCallback = Callable[[Frame], object]
_log = logging.getLogger(__name__)
CLOSE_WAIT = 2.0  # seconds close() waits for a running callback to return


class FrameCallbacks:
    """A listener (``put``) that queues up to ``depth`` frames and hands each to every callback."""

    def __init__(self, depth: int, name: str = "stereocam-callbacks"):
        self.queue = FrameQueue(name, depth, DropPolicy.DROP_OLDEST)
        self._callbacks: list[FrameCallback] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self.errors = 0  # callback calls that raised
        self.first_error: BaseException | None = None
        self._running: tuple[FrameCallback, int] | None = None  # the callback being called, and its frame
        self._thread.start()

    def add(self, fn: FrameCallback) -> None:
        """Register ``fn``; one already registered stays registered once (called once per frame)."""
        with self._lock:
            if fn not in self._callbacks:
                self._callbacks.append(fn)

    def remove(self, fn: FrameCallback) -> bool:
        """False if ``fn`` was not registered."""
        with self._lock:
            if fn not in self._callbacks:
                return False
            self._callbacks.remove(fn)
            return True

    def __len__(self) -> int:
        with self._lock:
            return len(self._callbacks)

    def put(self, frame: Frame) -> None:
        self.queue.put(frame)

    def _run(self) -> None:
        while not self._stop.is_set():
            frame = self.queue.get(0.1)
            if frame is None:
                continue
            with self._lock:
                callbacks = list(self._callbacks)
            for fn in callbacks:
                if self._stop.is_set():  # closed: no callback is called any more
                    return
                self._running = (fn, frame.sequence)
                try:
                    fn(frame)
                except BaseException as exc:  # reported, counted and re-raisable via check()
                    _log.error("frame callback %r raised on frame %d: %r", fn, frame.sequence, exc,
                               exc_info=exc)
                    if self.first_error is None:
                        self.first_error = exc
                    self.errors += 1
                finally:
                    self._running = None

    def check(self) -> None:
        """Raise CallbackError from the first exception a callback raised, if any (and forget it)."""
        exc, self.first_error = self.first_error, None
        if exc is not None:
            raise CallbackError(f"a frame callback raised {exc!r} ({self.errors} failed calls so far)") from exc

    def close(self, timeout: float = CLOSE_WAIT) -> bool:
        """Call no callback any more; wait up to ``timeout`` s for a running one to return (not when
        called from a callback). True if the thread has ended; else a WARNING names the callback still
        running, and the thread ends as soon as it returns (a thread cannot be stopped from outside)."""
        self._stop.set()
        if threading.current_thread() is self._thread:
            return False
        self._thread.join(timeout)
        running = self._running
        if self._thread.is_alive() and running is not None:
            _log.warning("frame callback %r still runs on frame %d after %.3g s: close() returns without it; "
                         "its thread (%s) ends when it returns", running[0], running[1], timeout,
                         self._thread.name)
        return not self._thread.is_alive()
