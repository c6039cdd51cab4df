"""One trigger line shared by simulator processes on this machine (``--trigger-line NAME``).

The line is a directory under the temp dir. Every process with heads on it binds a Unix datagram
socket there and a thread hands each pulse to its heads. Whoever drives the line (a master
simulator, a test) numbers the pulse from a counter file in the directory (locked, so the ids stay
the line's pulse numbers whoever drives it) and sends (trigger id, host-monotonic instant of the
edge) to every socket; a socket whose process has gone is removed. CLOCK_MONOTONIC is one clock
for every process on the machine, so the instant means the same thing to every head.
"""
from __future__ import annotations

import fcntl
import itertools
import os
import socket
import struct
import tempfile
import threading
import time
from pathlib import Path

from .trigger import OnPulse, check_line_name

PULSE = struct.Struct("<Qd")  # trigger id, instant
_ids = itertools.count()


def line_dir(name: str) -> Path:
    return Path(tempfile.gettempdir()) / f"stereocam-trigger-{check_line_name(name)}"


class SharedTriggerLine:
    """A trigger line (same interface as ``TriggerLine``) that reaches heads in other processes."""

    def __init__(self, name: str):
        self.name = name
        self.dir = line_dir(name)
        self.dir.mkdir(exist_ok=True)
        self._heads: list[OnPulse] = []
        self._lock = threading.Lock()
        self._sock: socket.socket | None = None
        self._path: Path | None = None
        self._thread: threading.Thread | None = None
        self._out = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self._out.setblocking(False)  # a listener that stopped reading must not stall the driver

    def attach(self, on_pulse: OnPulse) -> None:
        with self._lock:
            self._heads.append(on_pulse)
            if self._sock is None:  # this process listens from its first head on
                self._path = self.dir / f"{os.getpid()}-{next(_ids)}.sock"
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
                self._sock.bind(str(self._path))
                self._sock.settimeout(0.2)
                self._thread = threading.Thread(target=self._listen, args=(self._sock,), name="trigger-line",
                                                daemon=True)
                self._thread.start()

    def detach(self, on_pulse: OnPulse) -> None:
        with self._lock:
            if on_pulse in self._heads:
                self._heads.remove(on_pulse)

    def _listen(self, sock: socket.socket) -> None:
        while self._sock is sock:
            try:
                data = sock.recv(PULSE.size)
            except socket.timeout:
                continue
            except OSError:  # closed
                return
            if len(data) != PULSE.size:
                continue
            tid, instant = PULSE.unpack(data)
            with self._lock:
                heads = list(self._heads)
            for head in heads:
                head(tid, instant)

    def _next_id(self) -> int:
        fd = os.open(self.dir / "pulses", os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            raw = os.pread(fd, 8, 0)
            tid = (int.from_bytes(raw, "little") if len(raw) == 8 else 0) + 1
            os.pwrite(fd, tid.to_bytes(8, "little"), 0)
            return tid
        finally:
            os.close(fd)

    def pulse(self, instant: float | None = None) -> int:
        """Raise the line once (at ``instant``, host monotonic; default now); returns the trigger id."""
        instant = time.monotonic() if instant is None else instant
        tid = self._next_id()
        data = PULSE.pack(tid, instant)
        for path in self.dir.glob("*.sock"):
            try:
                self._out.sendto(data, str(path))
            except (ConnectionRefusedError, FileNotFoundError):  # its process is gone
                path.unlink(missing_ok=True)
            except BlockingIOError:  # a listener that stopped reading misses this edge
                pass
        return tid

    @property
    def pulses(self) -> int:
        """The line's pulse count so far."""
        try:
            raw = (self.dir / "pulses").read_bytes()
        except FileNotFoundError:
            return 0
        return int.from_bytes(raw, "little") if len(raw) == 8 else 0

    def close(self) -> None:
        with self._lock:
            self._heads.clear()
            sock, self._sock = self._sock, None
        if sock is not None:
            if self._thread is not None:
                self._thread.join(timeout=1)
            sock.close()
            if self._path is not None:
                self._path.unlink(missing_ok=True)
        self._out.close()
        if not any(self.dir.glob("*.sock")):  # the last one on the line tidies up
            (self.dir / "pulses").unlink(missing_ok=True)
            try:
                self.dir.rmdir()
            except OSError:
                pass
