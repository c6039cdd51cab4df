"""Serve a SimulatedCamera over a pseudo-terminal or a TCP socket until told to stop."""
from __future__ import annotations

import os
import select
import socket
import threading
import tty

from ..firmware import SimulatedCamera

READ_CHUNK = 65536


class PtyServer:
    """The firmware behind the master side of a pty; hosts open ``path`` (the slave) with pyserial."""

    def __init__(self, sim: SimulatedCamera):
        self.sim = sim
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no line discipline: an 8-bit clean wire
        self.path = os.ttyname(self._slave)
        self._stop = threading.Event()
        self._wlock = threading.Lock()

    @property
    def url(self) -> str:
        return self.path

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        with self._wlock:
            while view and not self._stop.is_set():
                try:
                    n = os.write(self._master, view)
                    view = view[n:]
                except BlockingIOError:
                    select.select([], [self._master], [], 0.1)

    def serve_forever(self) -> None:
        os.set_blocking(self._master, False)
        self.sim.attach(self._write)
        while not self._stop.is_set():
            ready, _, _ = select.select([self._master], [], [], 0.1)
            if not ready:
                continue
            try:
                data = os.read(self._master, READ_CHUNK)
            except (BlockingIOError, InterruptedError):
                continue
            except OSError:  # EIO while no host holds the slave open: wait for the next one
                self._stop.wait(0.05)
                continue
            if data:
                self.sim.receive(data)

    def shutdown(self) -> None:
        self._stop.set()

    def close(self) -> None:
        self.shutdown()
        self.sim.detach()
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass


class TcpServer:
    """The firmware behind a listening TCP socket, one host connection at a time.

    A host that stops reading for ``send_timeout`` seconds is dropped (the send fails, the device
    detaches and stops streaming), so a wedged client cannot hold the camera forever.
    """

    def __init__(self, sim: SimulatedCamera, host: str = "127.0.0.1", port: int = 0, send_timeout: float = 5.0):
        self.sim = sim
        self.send_timeout = send_timeout
        self._sock = socket.create_server((host, port))
        self._sock.settimeout(0.1)
        self.address = self._sock.getsockname()[:2]
        self._stop = threading.Event()

    @property
    def url(self) -> str:
        return f"socket://{self.address[0]}:{self.address[1]}"

    def serve_forever(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._sock.accept()
            except (socket.timeout, OSError):
                continue
            with conn:
                self._serve(conn)

    def _serve(self, conn: socket.socket) -> None:
        conn.settimeout(self.send_timeout)  # bounds sendall; recv only runs when select says ready
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sim.attach(conn.sendall)
        try:
            while not self._stop.is_set() and self.sim.attached:  # a failed send detaches the sim
                ready, _, _ = select.select([conn], [], [], 0.1)
                if not ready:
                    continue
                data = conn.recv(READ_CHUNK)
                if not data:
                    break
                self.sim.receive(data)
        except OSError:
            pass
        finally:
            self.sim.detach()  # the host hung up: stop streaming, drop output

    def shutdown(self) -> None:
        self._stop.set()

    def close(self) -> None:
        self.shutdown()
        self.sim.detach()
        self._sock.close()
