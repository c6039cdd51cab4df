"""Device side of frame repair (protocol 1.2, SPEC §13): the chunk size the host asked for, and
the last few captures' planes kept so damaged or missing parts can be sent again on request."""
from __future__ import annotations

import collections
import threading
from dataclasses import dataclass
from typing import Callable

from stereocam.protocol import messages as m

from ..link_layer.dispatcher import Handler

KEPT_CAPTURES = 8  # recent captures whose planes stay available for FRAME_RESEND

Emit = Callable[[bytes], bool]  # sends one message; False once the link is gone


@dataclass
class _Kept:
    planes: dict[int, memoryview]
    status: int = m.FRAME_OK


class FrameRepair:
    """Chunking and resend cache of one device; a new host link starts from the 1.1 defaults.
    ``emit`` sends one message on the host link (resent FRAME_DATA goes before the reply)."""

    def __init__(self, emit: Emit, keep: int = KEPT_CAPTURES):
        self._emit = emit
        self.keep = keep
        self.chunk = m.MAX_FRAME_CHUNK
        self._lock = threading.Lock()
        self._kept: collections.OrderedDict[int, _Kept] = collections.OrderedDict()
        self.resent_chunks = 0

    def handlers(self) -> dict[int, Handler]:
        return {m.MsgType.SET_FRAME_LINK: self.set_link, m.MsgType.FRAME_RESEND: self.resend}

    def reset(self) -> None:
        """A new host: default chunk size, nothing kept from the last host's stream."""
        with self._lock:
            self.chunk = m.MAX_FRAME_CHUNK
            self._kept.clear()

    def set_link(self, msg: m.SetFrameLink) -> m.FrameLink:
        """SET_FRAME_LINK: 0 restores the default; other sizes are clamped to what the device supports."""
        size = msg.chunk_size or m.MAX_FRAME_CHUNK
        self.chunk = max(m.MIN_FRAME_CHUNK, min(size, m.MAX_FRAME_CHUNK))
        return m.FrameLink(self.chunk, self.keep)

    def remember(self, sequence: int, planes: dict[int, memoryview]) -> None:
        """A capture about to be sent (its plane bytes must not change afterwards)."""
        with self._lock:
            self._kept[sequence] = _Kept(planes)
            while len(self._kept) > self.keep:
                self._kept.popitem(last=False)

    def chunks(self, sequence: int, plane: int, data: memoryview, start: int = 0, end: int | None = None):
        """The FRAME_DATA messages carrying ``data[start:end]`` of one plane, at the link's chunk size."""
        end = len(data) if end is None else min(end, len(data))
        step = self.chunk
        for off in range(start, end, step):
            yield m.encode(m.FrameData(sequence, plane, off, data[off:min(off + step, end)]))

    def resend(self, msg: m.FrameResend) -> m.FrameResent:
        """FRAME_RESEND: the requested ranges as FRAME_DATA (sent before the reply this returns)."""
        with self._lock:
            kept = self._kept.get(msg.sequence)
        if kept is None:
            return m.FrameResent(msg.sequence, m.RESEND_GONE, 0, 0)
        sent = 0
        for plane, offset, length in msg.ranges:
            data = kept.planes.get(plane)
            if data is None or offset >= len(data):
                continue
            for wire in self.chunks(msg.sequence, plane, data, offset, offset + length):
                if not self._emit(wire):
                    return m.FrameResent(msg.sequence, m.RESEND_GONE, kept.status, sent)
                sent += 1
        self.resent_chunks += sent
        return m.FrameResent(msg.sequence, m.RESEND_SENT, kept.status, sent)
