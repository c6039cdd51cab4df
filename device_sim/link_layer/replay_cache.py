"""The device's replay cache (SPEC §7): a RESEND of an answered request gets the same bytes back
and is never executed twice."""
from __future__ import annotations

import collections

from stereocam.protocol.framing import FLAG_RESEND, Packet

RESEND_CACHE = 64  # request ids remembered (reference firmware)


class ReplayCache:
    """The encoded reply of the last ``size`` request ids, with the request type they answered."""

    def __init__(self, size: int = RESEND_CACHE):
        self.size = size
        self._replies: collections.OrderedDict[int, tuple[int, bytes]] = collections.OrderedDict()

    def replay(self, packet: Packet) -> bytes | None:
        """The cached reply if ``packet`` is a RESEND of a request of the same type, else None."""
        cached = self._replies.get(packet.request_id)
        if packet.flags & FLAG_RESEND and cached is not None and cached[0] == packet.msg_type:
            return cached[1]
        return None

    def store(self, packet: Packet, wire: bytes) -> None:
        """Remember ``wire`` as the answer to ``packet``; the least recently answered id goes first."""
        self._replies[packet.request_id] = (packet.msg_type, wire)
        self._replies.move_to_end(packet.request_id)
        while len(self._replies) > self.size:
            self._replies.popitem(last=False)

    def clear(self) -> None:
        """A new host: its request ids say nothing about the last one's."""
        self._replies.clear()
