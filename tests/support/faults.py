"""Fault injection between host and device (after pymodbus's NullModem.set_manipulator).

``FaultyTransport`` wraps any real transport; manipulators see every chunk written or read and
return what goes on instead (split, corrupted, dropped).
"""
from __future__ import annotations

from typing import Callable

from stereocam.transports.base import Transport
from stereocam.protocol.framing import Decoder, encode_frame

Manipulator = Callable[[bytes], bytes]


class FaultyTransport(Transport):
    def __init__(self, inner: Transport):
        self.inner = inner
        self.url = inner.url
        self.on_write: Manipulator = lambda b: b
        self.on_read: Manipulator = lambda b: b
        self.max_read: int | None = None  # deliver reads in pieces no larger than this

    def set_manipulator(self, *, write: Manipulator | None = None, read: Manipulator | None = None) -> None:
        if write is not None:
            self.on_write = write
        if read is not None:
            self.on_read = read

    def write(self, data: bytes) -> None:
        self.inner.write(self.on_write(data))

    def read(self, max_bytes: int, timeout: float) -> bytes:
        data = self.inner.read(min(max_bytes, self.max_read or max_bytes), timeout)
        return self.on_read(data)  # looked up after the read: a manipulator set meanwhile applies

    def close(self) -> None:
        self.inner.close()


class PacketFilter:
    """A read manipulator working on whole packets: ``rule(packet) -> bytes | None`` (None keeps it)."""

    def __init__(self, rule: Callable[[object], bytes | None]):
        self.decoder = Decoder()
        self.rule = rule

    def __call__(self, data: bytes) -> bytes:
        out = []
        for p in self.decoder.feed(data):
            replaced = self.rule(p)
            out.append(encode_frame(p.msg_type, p.request_id, p.payload, p.flags) if replaced is None else replaced)
        return b"".join(out)
