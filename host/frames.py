"""The frame assembler: builds the captures a user gets (frame_types.py) from the message stream.

FRAME_BEGIN opens a capture, FRAME_DATA chunks fill its planes, FRAME_END closes it. A capture
with a missing chunk, a chunk outside its plane or a byte count that disagrees with the trailer is
repaired by resends where the device can (frame_repair.py), else dropped and counted by reason; a
gap in sequence numbers is counted as lost. Nothing is hidden.
"""
from __future__ import annotations

import bisect
import logging
import threading
import time
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from stereocam.protocol import messages as m
from stereocam.protocol.params import Output
from stereocam.protocol.segmentation import PLANE_DTYPE, PLANE_ORDER, plane_size, planes_of

from .clock import ClockMap
from .frame_repair import MAX_REPAIRING, MAX_ROUNDS, REPAIR_WINDOW, Coverage, Ranges
from .frame_types import DisparityFormat, Frame, FrameStatus, StereoGeometry

__all__ = ["AssemblyStats", "DisparityFormat", "Frame", "FrameAssembler", "FrameStatus", "StereoGeometry"]


@dataclass
class AssemblyStats:
    frames: int = 0
    incomplete: int = 0  # a chunk or the trailer never arrived
    size_mismatch: int = 0  # chunk outside its plane or trailer disagrees
    device_errors: int = 0  # the device's trailer status was not OK
    orphan_chunks: int = 0  # chunks of a capture whose leader was lost
    bad_leaders: int = 0  # FRAME_BEGINs claiming sizes beyond the INFO limits: dropped, nothing allocated
    lost: int = 0  # sequence numbers never seen (dropped on the device or on the link)
    repair_requests: int = 0  # FRAME_RESEND requests sent (protocol 1.2)
    repaired: int = 0  # captures delivered complete thanks to resent parts

    @property
    def dropped(self) -> int:
        """Captures not assembled whole (delivered flawed ones included)."""
        return self.incomplete + self.size_mismatch + self.device_errors + self.lost + self.bad_leaders


_ALL_PLANES = sum(int(p) for p in PLANE_ORDER)
_log = logging.getLogger(__name__)


@dataclass
class _Building:
    begin: m.FrameBegin
    buffers: dict[int, bytearray]
    coverage: Coverage
    bad: bool = False
    deadline: float = 0.0  # while under repair
    rounds: int = 0


class FrameAssembler:
    """Consumes frame messages in order; hands each Frame to ``deliver`` (which must not block:
    it runs on the link's reader thread or a repair worker).

    Flawed captures are counted by reason and dropped, or, with ``deliver_incomplete``, delivered
    with their ``status`` set (as GigE/USB3 Vision SDKs hand out buffers marked incomplete).
    """

    def __init__(self, clock_map: ClockMap, deliver: Callable[[Frame], None], deliver_incomplete: bool = False):
        self.deliver_incomplete = deliver_incomplete
        self._deliver_to = deliver
        self.stats = AssemblyStats()  # written under the lock; read a consistent copy with snapshot()
        self._clock_map = clock_map
        self._cur: _Building | None = None
        self._last_seq: int | None = None
        self._limits: tuple[int, int] | None = None  # (max_width, max_height) from INFO
        self._lock = threading.RLock()  # messages come from the reader, repair outcomes from the worker
        self.repair: Callable[[int, Ranges], None] | None = None  # set when the device can resend (1.2)
        self.repair_window = REPAIR_WINDOW
        self._repairing: dict[int, _Building] = {}
        self._held: list[tuple[int, Frame]] = []  # complete frames waiting behind an older one under repair

    def set_limits(self, max_width: int, max_height: int) -> None:
        """What the device said in INFO; a FRAME_BEGIN beyond it (or before it is known) is dropped."""
        self._limits = (max_width, max_height)

    def snapshot(self) -> AssemblyStats:
        """A copy of the counters, taken while no message is being assembled."""
        with self._lock:
            return replace(self.stats)

    def reset(self) -> None:
        """Before a new stream: forget the last sequence (a gap across start is no loss) and a
        capture cut off by the stop."""
        with self._lock:
            self._last_seq = None
            self._cur = None
            self._repairing.clear()
            self._held.clear()

    def on_message(self, msg: m.Message) -> None:
        with self._lock:
            if isinstance(msg, m.FrameBegin):
                self._begin(msg)
            elif isinstance(msg, m.FrameData):
                self._data(msg)
            elif isinstance(msg, m.FrameEnd):
                self._end(msg)

    def _begin(self, b: m.FrameBegin) -> None:
        if self._cur is not None:  # its FRAME_END never came
            self._incomplete(self._cur)
            self._cur = None
        if not self._plausible(b):  # checked before a byte is allocated
            self.stats.bad_leaders += 1
            return
        if self._last_seq is not None and b.sequence > self._last_seq + 1:
            self.stats.lost += b.sequence - self._last_seq - 1
            _log.info("frames %d..%d lost (never seen on the link)", self._last_seq + 1, b.sequence - 1)
        self._last_seq = b.sequence
        sizes: dict[int, int] = {p: plane_size(p, b.width, b.height) for p in planes_of(b)}
        self._cur = _Building(b, {p: bytearray(k) for p, k in sizes.items()}, Coverage(sizes))

    def _plausible(self, b: m.FrameBegin) -> bool:
        if self._limits is None:
            return False
        max_w, max_h = self._limits
        return 0 < b.width <= max_w and 0 < b.height <= max_h and not b.planes & ~_ALL_PLANES

    def _data(self, d: m.FrameData) -> None:
        cur = self._cur
        if cur is None or cur.begin.sequence != d.sequence:
            cur = self._repairing.get(d.sequence)
        if cur is None:
            self.stats.orphan_chunks += 1
            return
        buf = cur.buffers.get(d.plane)
        if buf is None or d.offset + len(d.data) > len(buf):
            cur.bad = True
            return
        buf[d.offset:d.offset + len(d.data)] = d.data
        cur.coverage.add(d.plane, d.offset, len(d.data))

    def _end(self, e: m.FrameEnd) -> None:
        cur, self._cur = self._cur, None
        if cur is None or cur.begin.sequence != e.sequence:
            if cur is not None:
                self._incomplete(cur)
            return
        sent: dict[int, int] = {Output.LEFT: e.left_bytes, Output.RIGHT: e.right_bytes,
                                Output.DISPARITY: e.disparity_bytes, Output.CONFIDENCE: e.confidence_bytes}
        if e.status != m.FRAME_OK:
            self._flawed(cur, FrameStatus.DEVICE_ERROR)
        elif cur.bad or any(sent[p] != len(buf) for p, buf in cur.buffers.items()):
            self._flawed(cur, FrameStatus.SIZE_MISMATCH)
        elif not cur.coverage.complete():
            self._incomplete(cur)
        else:
            self._deliver(self._frame(cur, FrameStatus.COMPLETE))

    # -- repair (SPEC §13) --------------------------------------------------------------------
    def _incomplete(self, cur: _Building) -> None:
        """A capture with bytes (or its trailer) missing: repaired if the device can resend, else dropped."""
        if self.repair is None or cur.bad:
            self._flawed(cur, FrameStatus.MISSING_DATA)
            return
        cur.deadline = time.monotonic() + self.repair_window
        self._repairing[cur.begin.sequence] = cur
        while len(self._repairing) > MAX_REPAIRING:
            self._give_up(min(self._repairing))
        self._ask(cur)

    def _ask(self, cur: _Building) -> None:
        assert self.repair is not None
        cur.rounds += 1
        self.stats.repair_requests += 1
        self.repair(cur.begin.sequence, cur.coverage.missing())

    def on_resent(self, sequence: int, reply: m.FrameResent | None) -> None:
        """The outcome of one FRAME_RESEND (None: no usable reply). The resent chunks came before it."""
        with self._lock:
            cur = self._repairing.get(sequence)
            if cur is None:
                return
            if reply is not None and reply.result == m.RESEND_SENT and reply.frame_status != m.FRAME_OK:
                self._give_up(sequence, FrameStatus.DEVICE_ERROR)
            elif reply is not None and reply.result == m.RESEND_SENT and cur.coverage.complete() and not cur.bad:
                del self._repairing[sequence]
                self.stats.repaired += 1
                self._deliver(self._frame(cur, FrameStatus.COMPLETE))
            elif ((reply is not None and reply.result == m.RESEND_GONE) or cur.bad or cur.rounds >= MAX_ROUNDS
                  or time.monotonic() > cur.deadline):
                self._give_up(sequence)
            else:
                self._ask(cur)
            self._release_held()

    def _give_up(self, sequence: int, status: FrameStatus = FrameStatus.MISSING_DATA) -> None:
        self._flawed(self._repairing.pop(sequence), status)
        self._release_held()

    def _flawed(self, cur: _Building, status: FrameStatus) -> None:
        counter = {FrameStatus.MISSING_DATA: "incomplete", FrameStatus.SIZE_MISMATCH: "size_mismatch",
                   FrameStatus.DEVICE_ERROR: "device_errors"}[status]
        setattr(self.stats, counter, getattr(self.stats, counter) + 1)
        _log.info("frame %d dropped: %s", cur.begin.sequence, status.value)
        if self.deliver_incomplete:
            self._deliver(self._frame(cur, status))

    def _frame(self, cur: _Building, status: FrameStatus) -> Frame:
        b = cur.begin
        planes = {p: np.frombuffer(buf, dtype=PLANE_DTYPE[p]).reshape(b.height, b.width)
                  for p, buf in cur.buffers.items()}
        disp = planes.get(Output.DISPARITY)
        return Frame(
            b.sequence, b.trigger_id, b.device_time_us, self._clock_map.to_host(b.device_time_us),
            planes.get(Output.LEFT), planes.get(Output.RIGHT),
            disp.astype(np.int16, copy=False) if disp is not None else None, b.exposure_us, b.gain,
            b.width, b.height, bool(b.flags & m.FRAME_RECTIFIED),
            DisparityFormat(b.subpixel, b.min_disparity, b.num_disparities, b.invalid_disparity),
            StereoGeometry(b.focal_px, b.cx, b.cy, b.baseline_m, b.calibration_id), status,
            confidence=planes.get(Output.CONFIDENCE))

    def _deliver(self, frame: Frame) -> None:
        """In sequence order: a frame waits behind an older capture still under repair."""
        if self._repairing and min(self._repairing) < frame.sequence:
            bisect.insort(self._held, (frame.sequence, frame), key=lambda h: h[0])
            return
        self._enqueue(frame)

    def _release_held(self) -> None:
        oldest = min(self._repairing, default=None)
        while self._held and (oldest is None or self._held[0][0] < oldest):
            self._enqueue(self._held.pop(0)[1])

    def _enqueue(self, frame: Frame) -> None:
        self.stats.frames += frame.status is FrameStatus.COMPLETE
        self._deliver_to(frame)
