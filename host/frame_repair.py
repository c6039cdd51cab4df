"""Host side of frame repair (protocol 1.2, SPEC §13): which bytes of a capture are still missing,
and the worker that asks the device to send them again without blocking the reader thread."""
from __future__ import annotations

import bisect
import queue
import threading
from typing import Callable

from stereocam.protocol import messages as m
from stereocam.protocol.errors import StereoCamError

REPAIR_WINDOW = 3.0  # s after a capture's end (or its successor's start) to complete it by resends
MAX_ROUNDS = 8  # FRAME_RESEND requests per capture at most
MAX_REPAIRING = 8  # captures under repair at once (what the reference device keeps); older ones given up
REPAIR_THREADS = 3  # requests in flight at once, so one lost request does not stall the others

Ranges = tuple[tuple[int, int, int], ...]


class Coverage:
    """Which bytes of each plane have arrived (duplicates from resends count once): per plane the
    sorted, disjoint runs [start, end) received. Chunks come in order, so a chunk nearly always
    extends the last run: no per-byte bookkeeping (a VGA capture is over a megabyte)."""

    def __init__(self, sizes: dict[int, int]):
        self._sizes = dict(sizes)
        self._runs: dict[int, list[list[int]]] = {p: [] for p in sizes}

    def add(self, plane: int, offset: int, length: int) -> None:
        end = min(offset + length, self._sizes[plane])
        offset = max(offset, 0)
        if end <= offset:
            return
        runs = self._runs[plane]
        if not runs or offset > runs[-1][1]:  # after the last run: a new one
            runs.append([offset, end])
        elif offset >= runs[-1][0]:  # in order: extends (or repeats) the last run
            runs[-1][1] = max(runs[-1][1], end)
        else:  # a resent piece further back: merge every run it touches
            starts = [r[0] for r in runs]
            lo = bisect.bisect_right(starts, offset)
            if lo > 0 and runs[lo - 1][1] >= offset:
                lo -= 1
            hi = bisect.bisect_right(starts, end)  # runs[lo:hi] touch [offset, end)
            if lo < hi:
                offset, end = min(offset, runs[lo][0]), max(end, runs[hi - 1][1])
            runs[lo:hi] = [[offset, end]]

    def complete(self) -> bool:
        return all(n == 0 or self._runs[p] == [[0, n]] for p, n in self._sizes.items())

    def missing(self, limit: int = m.MAX_RESEND_RANGES) -> Ranges:
        """Up to ``limit`` (plane, offset, length) runs of bytes not yet received, in order."""
        out: list[tuple[int, int, int]] = []
        for plane, size in self._sizes.items():
            at = 0
            for start, end in [*self._runs[plane], [size, size]]:
                if start > at:
                    out.append((plane, at, start - at))
                at = end
            if len(out) >= limit:
                break
        return tuple(out[:limit])


class RepairWorker:
    """Sends FRAME_RESEND requests from a few threads and reports each outcome (the reply, or None
    when it failed) to ``on_result``; a bug there ends the link via ``on_error``. The threads start
    with the first request: a link that never loses a byte never runs them."""

    def __init__(self, request: Callable[[m.Message], m.Message],
                 on_result: Callable[[int, m.FrameResent | None], None], on_error: Callable[[BaseException], None]):
        self._request = request
        self._on_result = on_result
        self._on_error = on_error
        self._jobs: queue.SimpleQueue[tuple[int, Ranges] | None] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._threads: list[threading.Thread] = []
        self._closed = False

    def submit(self, sequence: int, ranges: Ranges) -> None:
        with self._lock:
            if not self._threads and not self._closed:
                self._threads = [threading.Thread(target=self._run, name="stereocam-repair", daemon=True)
                                 for _ in range(REPAIR_THREADS)]
                for t in self._threads:
                    t.start()
        self._jobs.put((sequence, ranges))

    def _run(self) -> None:
        while (job := self._jobs.get()) is not None:
            sequence, ranges = job
            try:
                reply = self._request(m.FrameResend(sequence, ranges))
            except StereoCamError:
                reply = None
            try:
                self._on_result(sequence, reply if isinstance(reply, m.FrameResent) else None)
            except Exception as exc:  # surfaced as the link's error, never silent
                self._on_error(exc)
                return

    def close(self) -> None:
        with self._lock:
            self._closed = True
        for _ in self._threads:
            self._jobs.put(None)
        for t in self._threads:
            if threading.current_thread() is not t:
                t.join(timeout=2)
