"""Trigger and capture timing: free-run at a frame rate, software triggers, external line pulses.

One worker thread per device. Every exposure the sensor makes gets the next sequence number, so
an exposure the pipeline could not deliver leaves a visible gap (and counts as dropped).
"""
from __future__ import annotations

import collections
import logging
import threading
from dataclasses import dataclass
from typing import Callable

from stereocam.protocol.params import TriggerMode

from ..clock import REAL_CLOCK, Clock

TRIGGER_QUEUE_DEPTH = 2
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CaptureRequest:
    sequence: int
    trigger_id: int
    time: float  # host monotonic instant of the exposure
    epoch: int  # which start() this capture belongs to


class CaptureEngine:
    """Decides when exposures happen (on ``timebase``) and hands each to ``produce`` on the worker thread."""

    def __init__(self, produce: Callable[[CaptureRequest], None], timebase: Clock = REAL_CLOCK):
        self._produce = produce
        self._timebase = timebase
        self._cond = threading.Condition()
        self._queue: collections.deque[CaptureRequest] = collections.deque()
        self._streaming = False
        self._mode = TriggerMode.FREE_RUN
        self._period = 1 / 30
        self._next = 0.0
        self._closed = False
        self.epoch = 0  # bumped by every start/stop: captures of an older epoch are never sent
        self.sequence = 0
        self.dropped = 0
        self.captured = 0
        self._producing = False  # an exposure is being produced on the worker thread
        self._thread: threading.Thread | None = None  # started by the first start()
        self.on_streaming: Callable[[bool], None] = lambda streaming: None  # told after every start/stop

    @property
    def streaming(self) -> bool:
        return self._streaming

    def start(self, mode: TriggerMode, fps: int) -> None:
        with self._cond:
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="capture", daemon=True)
                self._thread.start()
            self._mode = TriggerMode(mode)
            self._period = 1.0 / fps
            self._next = self._timebase.monotonic()
            self._queue.clear()
            self._streaming = True
            self.epoch += 1
            self._cond.notify_all()
        self.on_streaming(True)

    def set_rate(self, fps: int) -> None:
        with self._cond:
            self._period = 1.0 / fps

    def stop(self) -> None:
        with self._cond:
            self._streaming = False
            self.epoch += 1
            self._queue.clear()
            self._cond.notify_all()
        self.on_streaming(False)

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._streaming = False
            self._cond.notify_all()
        self.on_streaming(False)
        if self._thread is not None and threading.current_thread() is not self._thread:
            self._thread.join(timeout=5)

    def trigger(self, trigger_id: int, source: TriggerMode, at: float | None = None) -> CaptureRequest | None:
        """Queue one exposure for a trigger from ``source`` (exposing at host-monotonic ``at``,
        default now); None if not accepted.

        A pulse that finds the queue full still consumes a sequence number (it is a real missed
        exposure, counted as dropped); a software trigger is refused instead so the host knows.
        """
        with self._cond:
            if not self._streaming or self._mode != source:
                return None
            if len(self._queue) >= TRIGGER_QUEUE_DEPTH:
                if source == TriggerMode.EXTERNAL:
                    self.sequence += 1
                    self.dropped += 1
                return None
            self.sequence += 1
            instant = self._timebase.monotonic() if at is None else at
            req = CaptureRequest(self.sequence, trigger_id, instant, self.epoch)
            self._queue.append(req)
            self._cond.notify_all()
            return req

    def _next_request(self) -> CaptureRequest | None:
        with self._cond:
            if self._closed:
                return None
            if not self._streaming:
                self._cond.wait(0.05)
                return None
            if self._mode != TriggerMode.FREE_RUN:
                if not self._queue:
                    self._cond.wait(0.05)
                return self._taken(self._queue.popleft()) if self._queue else None
            now = self._timebase.monotonic()
            if now < self._next:
                self._cond.wait(min(self._next - now, 0.05))
                return None
            missed = int((now - self._next) / self._period)  # exposures the pipeline was too busy for
            self.sequence += missed
            self.dropped += missed
            t = self._next + missed * self._period
            self._next = t + self._period
            self.sequence += 1
            return self._taken(CaptureRequest(self.sequence, 0, t, self.epoch))

    def _taken(self, req: CaptureRequest) -> CaptureRequest:
        """Under ``_cond``: ``req`` leaves the queue (or the timer) for the worker, which is busy
        from this moment until ``produce`` returns."""
        self._producing = True
        return req

    def count_drop(self) -> None:
        """A later pipeline stage failed on a capture: it counts as dropped."""
        with self._cond:
            self.dropped += 1

    @property
    def idle(self) -> bool:
        """Not producing an exposure now (stopped, or between two)."""
        return not self._producing

    def current(self, req: CaptureRequest) -> bool:
        """Whether ``req`` still belongs to the running stream (not stopped or restarted since)."""
        return self._streaming and req.epoch == self.epoch

    def _run(self) -> None:
        while not self._closed:
            req = self._next_request()
            if req is None:
                continue
            self.captured += 1
            try:
                self._produce(req)
            except Exception:  # a firmware bug must not kill the capture thread: log, count, go on
                log.exception("capture %d failed", req.sequence)
                self.dropped += 1
            finally:
                self._producing = False
