"""Serve a SimulatedCamera over a pseudo-terminal or a TCP socket until told to stop.

Both follow SPEC §9: a host silent for the link timeout is dropped by the device's watchdog (the
transport's ``hang_up``), a host that stops reading is dropped after ``send_timeout`` seconds of a
send making no progress, and a new host never receives output meant for an earlier one.
"""
from __future__ import annotations

import os
import select
import socket
import termios
import threading
import time
import tty

from stereocam.protocol import messages as m
from stereocam.protocol.errors import ConfigError, ErrorCode

from ..firmware import SimulatedCamera

READ_CHUNK = 65536
SEND_TIMEOUT_S = 5.0
REFUSE_LINGER_S = 0.5  # a refused client's bytes are read and discarded this long, so the NACK is not reset away
WAIT_FOR_SLOT_S = 2.0  # a second TCP client waits this long for the host to leave before it is refused
PORT_MAX = 65535


class PtyServer:
    """The firmware behind the master side of a pty; hosts open ``path`` (the slave) with pyserial.

    A pty has no connections: after the device dropped a host (silence or a send timeout) the next
    bytes that arrive start a new link, and the output still queued for the old host is discarded.
    The server does not hold the slave open itself, so a host that closes it (or dies) shows at
    once (the master reads EIO while nobody holds the slave): the device detaches, which stops the
    stream, and the output the pty still holds is discarded. The device links up on a host's first
    bytes, so a host that opens the port the moment the server starts loses nothing it sent.
    """

    def __init__(self, sim: SimulatedCamera, send_timeout: float = SEND_TIMEOUT_S):
        self.sim = sim
        self.send_timeout = send_timeout
        self._master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no line discipline: an 8-bit clean wire (kept while the master is open)
        self.path = os.ttyname(slave)
        os.close(slave)
        self._stop = threading.Event()
        self._wlock = threading.Lock()
        self._session = 0  # bumped by every hang-up: a write of an older session gives up

    @property
    def url(self) -> str:
        return self.path

    def _write(self, data: bytes) -> None:
        """Bounded send: TimeoutError (an OSError: the link detaches and the stream stops) when the
        host reads nothing for ``send_timeout``; BrokenPipeError once the link was hung up."""
        view = memoryview(data)
        session = self._session
        with self._wlock:
            stalled_since = time.monotonic()
            while view and not self._stop.is_set():
                if self._session != session:
                    raise BrokenPipeError("the device dropped this host")
                try:
                    n = os.write(self._master, view)
                    view = view[n:]
                    stalled_since = time.monotonic()
                except BlockingIOError:
                    if time.monotonic() - stalled_since > self.send_timeout:
                        self.sim.counters["link_send_timeouts"] += 1
                        raise TimeoutError(f"the host read nothing for {self.send_timeout} s") from None
                    select.select([], [self._master], [], 0.05)

    def _hang_up(self) -> None:
        self._session += 1

    def _flush_output(self) -> None:
        """Discard the output the pty still holds for the last host. Never its input: a next host's
        first bytes may already be in it."""
        try:
            termios.tcflush(self._master, termios.TCOFLUSH)
        except termios.error:
            pass

    def _attach(self) -> None:
        """A new host (its first bytes arrived): discard what the pty still holds for the last one,
        then link up."""
        self._session += 1
        self._flush_output()
        self.sim.attach(self._write, self._hang_up)

    def _host_left(self) -> None:
        """Nobody holds the slave open: the host closed it or died; end its link at once."""
        if self.sim.attached:
            self._session += 1
            self.sim.detach()
            self._flush_output()

    def serve_forever(self) -> None:
        os.set_blocking(self._master, False)
        while not self._stop.is_set():
            ready, _, _ = select.select([self._master], [], [], 0.1)
            if not ready:
                continue
            try:
                data = os.read(self._master, READ_CHUNK)
            except (BlockingIOError, InterruptedError):
                continue
            except OSError:  # EIO while no host holds the slave open: the host left; wait for the next
                self._host_left()
                self._stop.wait(0.05)
                continue
            if data:
                if not self.sim.attached:  # a new host's first bytes: keep the rest of what it sent
                    self._attach()
                self.sim.receive(data)

    def shutdown(self) -> None:
        self._stop.set()

    def close(self) -> None:
        self.shutdown()
        self.sim.detach()
        try:
            os.close(self._master)
        except OSError:
            pass


TCP_CLOSE_WAIT = 8  # Linux tcp_info.tcpi_state: the peer has closed its side


def peer_closed(conn: socket.socket) -> bool:
    """Whether the peer of ``conn`` has closed its side (FIN received), even with its bytes still
    unread (Linux TCP_INFO; False where the platform cannot tell)."""
    try:
        return conn.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, 1)[0] == TCP_CLOSE_WAIT
    except (AttributeError, OSError):
        return False


def busy_nack(holder: str) -> bytes:
    """What a second TCP client hears before the device hangs up on it."""
    return m.encode(m.Nack(0, ErrorCode.BAD_STATE, 0, f"busy: another host ({holder}) holds this device; "
                           "nothing you sent was executed, connect again when it has left"))


class TcpServer:
    """The firmware behind a listening TCP socket, one host connection at a time.

    A second client is accepted and waits up to ``WAIT_FOR_SLOT_S`` for the host to leave (then it
    is served: a host that just closed may still have bytes the device works through); if the host
    stays, the client is told why with a NACK and closed, nothing it sent executed. A third client
    meanwhile is refused at once. A host that has closed its side or is silent past its link
    timeout (the default one when it turned the watchdog off) yields to the waiting client. A host that stops
    reading for ``send_timeout`` seconds is dropped (the send fails, the device detaches and stops
    streaming); one silent for the link timeout is dropped by the device's watchdog (SPEC §9).
    """

    def __init__(self, sim: SimulatedCamera, host: str = "127.0.0.1", port: int = 0,
                 send_timeout: float = SEND_TIMEOUT_S):
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= PORT_MAX:
            raise ConfigError(f"TCP port must be an integer 0..{PORT_MAX} (0: any free port), got {port!r}")
        self.sim = sim
        self.send_timeout = send_timeout
        self._sock = socket.create_server((host, port))
        self._sock.settimeout(0.1)
        self.address = self._sock.getsockname()[:2]
        self._stop = threading.Event()
        self._waiting: tuple[socket.socket, str, float] | None = None  # a client waiting for the slot, its deadline

    @property
    def url(self) -> str:
        return f"socket://{self.address[0]}:{self.address[1]}"

    def serve_forever(self) -> None:
        while not self._stop.is_set():
            if self._waiting is not None:  # the host left while a client waited: it is next
                conn, peer, _ = self._waiting
                self._waiting = None
            else:
                try:
                    conn, addr = self._sock.accept()
                except (socket.timeout, OSError):
                    continue
                peer = f"{addr[0]}:{addr[1]}"
            with conn:
                self._serve(conn, peer)

    def _knock(self, holder: str) -> None:
        """A client connects while ``holder`` has the device: it waits for the slot (one at a time)."""
        if self._waiting is not None:
            self._refuse(holder)
            return
        try:
            conn, addr = self._sock.accept()
        except OSError:
            return
        self._waiting = (conn, f"{addr[0]}:{addr[1]}", time.monotonic() + WAIT_FOR_SLOT_S)

    def _refuse_waiting(self, holder: str) -> None:
        """The waiting client's time is up: tell it why and hang up (in its own thread)."""
        if self._waiting is not None and time.monotonic() > self._waiting[2]:
            conn = self._waiting[0]
            self._waiting = None
            self.sim.counters["hosts_refused"] += 1
            threading.Thread(target=self._tell_busy, args=(conn, holder), name="tcp-refuse", daemon=True).start()

    def _refuse(self, holder: str) -> None:
        """Accept the waiting client and hang up on it (in its own thread: the host is not kept waiting)."""
        try:
            conn, _ = self._sock.accept()
        except OSError:
            return
        self.sim.counters["hosts_refused"] += 1
        threading.Thread(target=self._tell_busy, args=(conn, holder), name="tcp-refuse", daemon=True).start()

    @staticmethod
    def _tell_busy(conn: socket.socket, holder: str) -> None:
        with conn:
            conn.settimeout(REFUSE_LINGER_S)
            try:
                conn.sendall(busy_nack(holder))
                conn.shutdown(socket.SHUT_WR)
                deadline = time.monotonic() + REFUSE_LINGER_S
                while time.monotonic() < deadline and conn.recv(READ_CHUNK):  # discarded, never executed
                    pass
            except OSError:
                pass

    def _serve(self, conn: socket.socket, peer: str) -> None:
        conn.settimeout(self.send_timeout)  # bounds sendall; recv only runs when select says ready
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

        def hang_up() -> None:
            try:
                conn.shutdown(socket.SHUT_RDWR)  # wakes a sender blocked in sendall and this loop
            except OSError:
                pass

        self.sim.attach(conn.sendall, hang_up)
        try:
            while not self._stop.is_set() and self.sim.attached:  # a failed send or a drop detaches
                ready, _, _ = select.select([conn, self._sock], [], [], 0.1)
                if not self.sim.attached:  # dropped meanwhile: the waiting client is the next host
                    break
                if self._sock in ready:
                    self._knock(peer)
                # a host that has closed its side (its unread bytes answer no one), or one silent
                # with the watchdog off, yields: the waiting client is next
                if self._waiting is not None and (peer_closed(conn) or self.sim.heartbeat.yield_link()):
                    break
                self._refuse_waiting(peer)
                if conn not in ready:
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
        if self._waiting is not None:
            self._waiting[0].close()
