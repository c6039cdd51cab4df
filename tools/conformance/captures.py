"""Captures as the judge sees them: every FRAME_BEGIN / FRAME_DATA / FRAME_END, checked in order.

Unlike the SDK's frame assembler (which drops flawed captures and counts them), this log keeps
every capture with a list of the rules it broke (SPEC §8.1): messages of one capture share one
sequence, chunks are contiguous and ascending per plane, only announced planes are sent, the
trailer's byte counts match what arrived.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass, field

from stereocam.protocol import messages as m
from stereocam.protocol.params import Output
from stereocam.protocol.segmentation import PLANE_DTYPE, PLANE_ORDER

PLANE_BYTES = {int(p): PLANE_DTYPE[p].itemsize for p in PLANE_ORDER}


@dataclass
class Capture:
    begin: m.FrameBegin
    received: float  # host monotonic time the FRAME_BEGIN arrived
    data: dict[int, bytearray] = field(default_factory=dict)  # plane -> bytes, in arrival order
    end: m.FrameEnd | None = None
    problems: list[str] = field(default_factory=list)

    @property
    def sequence(self) -> int:
        return self.begin.sequence

    def plane_size(self, plane: int) -> int:
        return self.begin.width * self.begin.height * PLANE_BYTES[plane]


class CaptureLog:
    """Thread-safe record of the captures seen since the last ``clear``."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.captures: list[Capture] = []
        self.messages = 0  # every capture message ever received
        self.stray: list[str] = []  # FRAME_DATA / FRAME_END outside an open capture

    def clear(self) -> None:
        with self._lock:
            self.captures = []
            self.stray = []

    def snapshot(self) -> list[Capture]:
        with self._lock:
            return list(self.captures)

    def find(self, sequence: int) -> Capture | None:
        with self._lock:
            return next((c for c in self.captures if c.sequence == sequence), None)

    def on_message(self, msg: m.Message, now: float) -> None:
        with self._lock:
            self.messages += 1
            cur = self.captures[-1] if self.captures and self.captures[-1].end is None else None
            if isinstance(msg, m.FrameBegin):
                if cur is not None:
                    cur.problems.append(f"FRAME_BEGIN of sequence {msg.sequence} before this capture's FRAME_END")
                self.captures.append(Capture(msg, now))
            elif isinstance(msg, m.FrameData):
                if cur is None or cur.sequence != msg.sequence:
                    self.stray.append(f"FRAME_DATA of sequence {msg.sequence} outside its capture")
                else:
                    _add_chunk(cur, msg)
            elif isinstance(msg, m.FrameEnd):
                if cur is None or cur.sequence != msg.sequence:
                    self.stray.append(f"FRAME_END of sequence {msg.sequence} outside its capture")
                else:
                    cur.end = msg
                    _close(cur)


def _add_chunk(cur: Capture, d: m.FrameData) -> None:
    if not cur.begin.planes & d.plane or d.plane not in PLANE_BYTES:
        cur.problems.append(f"chunk of plane {d.plane}, not announced in planes=0x{cur.begin.planes:x}")
        return
    buf = cur.data.setdefault(d.plane, bytearray())
    if d.offset != len(buf):
        cur.problems.append(f"plane {d.plane} chunk at offset {d.offset}, expected {len(buf)} (contiguous, ascending)")
        return
    if d.offset + len(d.data) > cur.plane_size(d.plane):
        cur.problems.append(f"plane {d.plane} chunk runs past the plane's {cur.plane_size(d.plane)} bytes")
        return
    buf += d.data


def _close(cur: Capture) -> None:
    e = cur.end
    assert e is not None
    counts = {int(Output.LEFT): e.left_bytes, int(Output.RIGHT): e.right_bytes, int(Output.DISPARITY): e.disparity_bytes,
              int(Output.CONFIDENCE): e.confidence_bytes}
    for plane, sent in counts.items():
        want = cur.plane_size(plane) if cur.begin.planes & plane else 0
        got = len(cur.data.get(plane, b""))
        if sent != want or got != want:
            cur.problems.append(f"plane {plane}: FRAME_END says {sent} bytes, received {got}, plane size {want}")
