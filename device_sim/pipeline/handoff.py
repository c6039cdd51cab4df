"""Overlapping pipeline stages: one stage's thread hands each item to the next stage's thread.

The hand-off is a rendezvous: ``put`` returns once the worker has *taken* the item, so at most
one item is worked on while the next one is being prepared, and nothing piles up between the
stages (a slow later stage slows the earlier one down, whose own clock then counts the skipped
work). The numba kernels of both stages release the GIL, so the two threads run side by side.
"""
from __future__ import annotations

import logging
import threading
from typing import Callable, Generic, TypeVar

T = TypeVar("T")
log = logging.getLogger(__name__)


class Handoff(Generic[T]):
    """A worker thread running ``work`` on each item ``put`` to it, one at a time, in order.
    ``on_error(item)`` runs after ``work`` raised (the exception is logged; the worker goes on)."""

    def __init__(self, work: Callable[[T], None], on_error: Callable[[T], None], name: str):
        self._work = work
        self._on_error = on_error
        self._cond = threading.Condition()
        self._item: T | None = None
        self._working = False
        self._closed = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def put(self, item: T) -> None:
        """Give ``item`` to the worker; returns once it has started on it (or the hand-off closed)."""
        with self._cond:
            self._item = item
            self._cond.notify_all()
            while self._item is not None and not self._closed:
                self._cond.wait()

    @property
    def idle(self) -> bool:
        """Nothing handed over and nothing being worked on."""
        with self._cond:
            return self._item is None and not self._working

    def close(self) -> None:
        """Stop the worker after the item in hand (a waiting one is discarded)."""
        with self._cond:
            self._closed = True
            self._item = None
            self._cond.notify_all()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout=5)

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._item is None and not self._closed:
                    self._cond.wait()
                if self._closed:
                    return
                item, self._item = self._item, None
                assert item is not None  # the wait ends with an item or closed
                self._working = True
                self._cond.notify_all()
            try:
                self._work(item)
            except Exception:  # a firmware bug must not kill the stage: log, count, go on
                log.exception("pipeline stage %s failed", self._thread.name)
                self._on_error(item)
            finally:
                with self._cond:
                    self._working = False
