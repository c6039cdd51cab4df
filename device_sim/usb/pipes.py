"""Bulk endpoint FIFOs of a simulated device, with USB 2.0 packet semantics.

IN (device → host). Every ``push(data)`` is one device-side IN transfer: the firmware hands the
controller one buffer, which goes out as ``wMaxPacketSize`` packets. The transfer ends with a
short packet, or, when its length is a multiple of ``wMaxPacketSize`` (0 included), with a
zero-length packet (ZLP) -- what USB firmware sends so that the host's pending read completes
at a message end (Linux gadget drivers call it the ``zero`` flag). ``zlp=False`` models firmware
that forgets the ZLP: a host read then stays pending until its buffer fills or it times out.

A host bulk read of ``N`` bytes takes whole packets until the buffer is full, a short packet or
ZLP ends the transfer, or the timeout expires. As with libusb, a timeout after some bytes arrived
returns those bytes; with none it is ``USBTimeoutError``. A packet larger than the space left in
the buffer is a babble/overflow error (``EOVERFLOW``) and its data is lost: read in multiples of
``wMaxPacketSize``. Pushing blocks while ``capacity`` bytes are queued (USB flow control: the
controller NAKs until the host reads); closing the pipe (unplug) wakes every waiter, and the
firmware's blocked or later pushes raise ``BrokenPipeError``.

The bus has a speed: ``bytes_per_s`` of bulk payload. A host transfer occupies the bus for its
length divided by that rate, from when its first packet is taken (or the bus is done with the
previous transfer, if later), and completes only then; so a host cannot drain the FIFO faster
than the bus could carry it, and a firmware producing faster blocks on the full FIFO.

OUT (host → device). A bulk write is accepted while the firmware's receive buffer has room, and
each accepted chunk is handed to the firmware thread in order; a full buffer NAKs (the write
waits), and a timeout returns the partial count, or raises if nothing was accepted.
"""
from __future__ import annotations

import threading
import time
from collections import deque
from typing import Callable

from .errors import LibusbError, usb_error

Check = Callable[[], None]
"""Raises if the host handle doing the transfer went away; called on every wake-up."""


def _deadline(timeout_ms: int) -> float | None:
    """libusb semantics: timeout 0 means wait forever."""
    return None if timeout_ms <= 0 else time.monotonic() + timeout_ms / 1000.0


def _remaining(deadline: float | None) -> float | None:
    return None if deadline is None else deadline - time.monotonic()


class _Endpoint:
    """State shared by both directions: lock, halt (STALL) flag, closed flag, and how many
    transfers are blocked on it (``waiting``: a host read waiting for data, a write or push for room)."""

    def __init__(self, address: int) -> None:
        self.address = address
        self.cond = threading.Condition()
        self.halted = False
        self.closed = False
        self.waiting = 0

    def _wait(self, timeout: float | None = None) -> None:
        """``cond.wait`` (``cond`` held), counted in ``waiting`` while it blocks."""
        self.waiting += 1
        try:
            self.cond.wait(timeout)
        finally:
            self.waiting -= 1

    def halt(self) -> None:
        """STALL the endpoint: transfers fail with EPIPE until clear_halt()."""
        with self.cond:
            self.halted = True
            self.cond.notify_all()

    def clear_halt(self) -> None:
        with self.cond:
            self.halted = False
            self.cond.notify_all()

    def close(self) -> None:
        """Device gone: every waiter wakes; host transfers fail with ENODEV."""
        with self.cond:
            self.closed = True
            self.cond.notify_all()

    def wake(self) -> None:
        with self.cond:
            self.cond.notify_all()

    def _host_check(self, check: Check) -> None:
        if self.closed:
            raise usb_error(LibusbError.NO_DEVICE)
        check()
        if self.halted:
            raise usb_error(LibusbError.PIPE, f"endpoint 0x{self.address:02x} halted")


class InPipe(_Endpoint):
    """Device → host FIFO of IN transfers (see the module docstring for the packet rules)."""

    def __init__(self, address: int, max_packet: int, capacity: int, zlp: bool = True,
                 bytes_per_s: float = float("inf")) -> None:
        super().__init__(address)
        self.max_packet = max_packet
        self.bytes_per_s = bytes_per_s
        self._bus_free = 0.0  # monotonic instant the bus is done carrying the transfers so far
        self.capacity = capacity
        self.zlp = zlp
        self._queue: deque[list] = deque()  # [data: bytes, pos: int, zlp_pending: bool]
        self._queued = 0
        self._flushes = 0  # counts flush(): a push blocked across one is dropped

    @property
    def queued(self) -> int:
        """Bytes waiting for the host."""
        return self._queued

    def push(self, data: bytes) -> None:
        """Queue one IN transfer; blocks while the FIFO is full. Raises ``BrokenPipeError`` (an
        OSError, like writing to a closed socket) once the device is unplugged, so firmware
        threads never hang on a vanished host."""
        data = bytes(data)
        with self.cond:
            flushes = self._flushes
            while (not self.closed and self._queued and flushes == self._flushes
                   and self._queued + len(data) > self.capacity):
                self._wait()
            if self.closed:
                raise BrokenPipeError("USB device unplugged")
            if flushes != self._flushes:  # flushed while it waited: it belonged to what was dropped
                return
            zlp = self.zlp and len(data) % self.max_packet == 0
            if data or zlp:
                self._queue.append([data, 0, zlp])
                self._queued += len(data)
                self.cond.notify_all()

    def flush(self) -> None:
        """Drop everything queued (device reset), and what a blocked ``push`` was about to queue."""
        with self.cond:
            self._queue.clear()
            self._queued = 0
            self._flushes += 1
            self.cond.notify_all()

    def read_transfer(self, out: memoryview, timeout_ms: int, check: Check) -> int:
        """One host bulk IN transfer into ``out``; returns the byte count (0 for a lone ZLP)."""
        deadline = _deadline(timeout_ms)
        got = 0
        first: float | None = None  # when the bus started on this transfer
        with self.cond:
            while True:
                self._host_check(check)
                if self._queue:
                    if first is None:
                        first = max(time.monotonic(), self._bus_free)
                    got, done = self._take_packets(out, got)
                    self.cond.notify_all()  # room for a blocked writer
                    if done:
                        return self._on_the_wire(first, got)
                    continue
                left = _remaining(deadline)
                if left is not None and left <= 0:
                    if got:
                        return self._on_the_wire(first, got)
                    raise usb_error(LibusbError.TIMEOUT)
                self._wait(left)

    def _on_the_wire(self, first: float | None, got: int) -> int:
        """Hold the transfer (lock released) until the bus has carried its ``got`` bytes."""
        if first is None or self.bytes_per_s == float("inf"):
            return got
        end = first + got / self.bytes_per_s
        self._bus_free = end
        while (left := end - time.monotonic()) > 0 and not self.closed:
            self.cond.wait(left)
        return got

    def _take_packets(self, out: memoryview, got: int) -> tuple[int, bool]:
        """Move whole packets from the queue head into ``out``; (new count, transfer ended)."""
        mps = self.max_packet
        while self._queue:
            entry = self._queue[0]
            data, pos, zlp = entry
            rest = len(data) - pos
            room = len(out) - got
            if rest == 0:  # only the terminating ZLP (or nothing) is left of this transfer
                self._queue.popleft()
                if zlp:
                    return got, True
                continue
            if rest >= mps:
                n = min(rest // mps, room // mps) * mps
                if n == 0:
                    return self._overflow(entry, min(rest, mps))
            else:
                if rest > room:
                    return self._overflow(entry, rest)
                n = rest
            out[got:got + n] = memoryview(data)[pos:pos + n]
            got += n
            entry[1] = pos + n
            self._queued -= n
            if n < mps:  # a short packet ends the transfer
                self._queue.popleft()
                return got, True
            if entry[1] == len(data) and not zlp:
                self._queue.popleft()
            if got == len(out):
                return got, True
        return got, False

    def _overflow(self, entry: list, packet: int) -> tuple[int, bool]:
        """The device sent a packet bigger than the space left: babble; the packet is lost."""
        entry[1] += packet
        self._queued -= packet
        if entry[1] == len(entry[0]) and not entry[2]:
            self._queue.popleft()
        raise usb_error(LibusbError.OVERFLOW, "read length is not a multiple of wMaxPacketSize")


class OutPipe(_Endpoint):
    """Host → device FIFO feeding the firmware's receive thread."""

    def __init__(self, address: int, capacity: int) -> None:
        super().__init__(address)
        self.capacity = capacity
        self._queue: deque[bytes] = deque()
        self._queued = 0

    def write_transfer(self, data: memoryview, timeout_ms: int, check: Check) -> int:
        """One host bulk OUT transfer; returns how many bytes the device accepted."""
        deadline = _deadline(timeout_ms)
        sent = 0
        with self.cond:
            self._host_check(check)
            if len(data) == 0:
                return 0  # a ZLP: carries no bytes to a stream-oriented firmware
            while sent < len(data):
                self._host_check(check)
                room = self.capacity - self._queued
                if room > 0:
                    chunk = bytes(data[sent:sent + room])
                    self._queue.append(chunk)
                    self._queued += len(chunk)
                    sent += len(chunk)
                    self.cond.notify_all()
                    continue
                left = _remaining(deadline)
                if left is not None and left <= 0:
                    if sent:
                        return sent
                    raise usb_error(LibusbError.TIMEOUT)
                self._wait(left)
        return sent

    def take(self) -> bytes | None:
        """Next chunk for the firmware, blocking; None once the device is unplugged."""
        with self.cond:
            while not self._queue and not self.closed:
                self.cond.wait()
            if self.closed:
                return None
            chunk = self._queue.popleft()
            self._queued -= len(chunk)
            self.cond.notify_all()
            return chunk

    def flush(self) -> None:
        with self.cond:
            self._queue.clear()
            self._queued = 0
            self.cond.notify_all()
