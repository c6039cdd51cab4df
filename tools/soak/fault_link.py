"""Fault injection between host and device (after pymodbus's NullModem.set_manipulator), for the
tests and ``stereocam soak``.

``FaultyTransport`` wraps any real transport; manipulators see every chunk written or read and
return what goes on instead (split, corrupted, dropped). ``LineNoise`` is a noisy line: bytes
replaced or lost at given rates, optional latency.
"""
from __future__ import annotations

import random
import time
from typing import Callable

import numpy as np

from stereocam.transports.base import Transport

Manipulator = Callable[[bytes], bytes]


class FaultyTransport(Transport):
    def __init__(self, inner: Transport):
        self.inner = inner
        self.url = inner.url
        self.frame_chunk = inner.frame_chunk  # a test may ask for serial-sized chunks on any link
        self.on_write: Manipulator = lambda b: b
        self.on_read: Manipulator = lambda b: b
        self.max_read: int | None = None  # deliver reads in pieces no larger than this
        self.max_write: int | None = None  # split writes into pieces of 1..max_write bytes

    def set_manipulator(self, *, write: Manipulator | None = None, read: Manipulator | None = None) -> None:
        if write is not None:
            self.on_write = write
        if read is not None:
            self.on_read = read

    def write(self, data: bytes) -> None:
        data = self.on_write(data)
        if not self.max_write:
            self.inner.write(data)
            return
        pos = 0
        while pos < len(data):
            n = random.randint(1, self.max_write)
            self.inner.write(data[pos:pos + n])
            pos += n

    def read(self, max_bytes: int, timeout: float) -> bytes:
        data = self.inner.read(min(max_bytes, self.max_read or max_bytes), timeout)
        return self.on_read(data)  # looked up after the read: a manipulator set meanwhile applies

    def close(self) -> None:
        self.inner.close()


class LineNoise:
    """Each byte replaced by another value with probability ``flip``, lost with probability ``drop``;
    each chunk delayed by up to ``latency`` seconds. Seeded; counts what it did."""

    def __init__(self, flip: float = 0.0, drop: float = 0.0, latency: float = 0.0, seed: int = 0):
        self.flip, self.drop, self.latency = flip, drop, latency
        self.flipped = self.dropped = 0
        self._rng = np.random.default_rng(seed)

    def __call__(self, data: bytes) -> bytes:
        if self.latency and data:
            time.sleep(self._rng.uniform(0, self.latency))
        n = len(data)
        k = self._rng.binomial(n, self.flip) if n and self.flip else 0
        d = self._rng.binomial(n, self.drop) if n and self.drop else 0
        if not k and not d:
            return data
        b = np.frombuffer(data, dtype=np.uint8).copy()
        if k:
            b[self._rng.integers(0, n, k)] ^= self._rng.integers(1, 256, k, dtype=np.uint8)
            self.flipped += k
        if d:
            b = np.delete(b, self._rng.integers(0, n, d))
            self.dropped += d
        return b.tobytes()
