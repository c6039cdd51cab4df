"""Anything pyserial opens: device paths (a pty, /dev/ttyACM0), ``socket://``, ``rfc2217://``, ``loop://``.

A serial line (a device path) asks the device for small frame chunks (SPEC §13: a bit error costs a
small resend). A URL may ask for them too with ``?frame_chunk=N`` (N bytes, 256..131072): a
``socket://`` that reaches a serial line through a network bridge (ser2net) gets that line's
errors inside TCP. The option is taken out of the URL before pyserial sees it.
"""
from __future__ import annotations

import select
import socket
from typing import TYPE_CHECKING
from urllib.parse import parse_qsl, urlencode, urlsplit, urlunsplit

import serial

from stereocam.protocol.errors import ConfigError, DisconnectedError, TransportError
from stereocam.protocol.messages import MAX_FRAME_CHUNK, MIN_FRAME_CHUNK

from stereocam.protocol.usb_identity import CAMERA_IDS

from .base import Transport

if TYPE_CHECKING:
    from ..discovery import DeviceEntry


SERIAL_FRAME_CHUNK = 1024  # a noisy serial line loses (and resends) a small chunk, not 128 KiB
FRAME_CHUNK_OPTION = "frame_chunk"


class SerialTransport(Transport):
    """A pyserial port as a byte pipe; a serial line (a device path, not a network URL) asks for
    small frame chunks, any URL for those its ``frame_chunk`` option names."""

    def __init__(self, port: serial.SerialBase, url: str, frame_chunk: int | None = None):
        self.port = port
        self.url = url
        self.frame_chunk = frame_chunk or (None if "://" in url else SERIAL_FRAME_CHUNK)

    def write(self, data: bytes) -> None:
        try:
            self.port.write(data)
        except (serial.SerialException, OSError) as exc:
            raise DisconnectedError(f"write to {self.url} failed: {exc}") from exc

    def _timeout(self, seconds: float) -> None:
        if self.port.timeout != seconds:  # reconfiguring a tty costs syscalls: only on change
            self.port.timeout = seconds

    def read(self, max_bytes: int, timeout: float) -> bytes:
        """Wait up to ``timeout`` for one byte, then take whatever else is ready without waiting.

        (``in_waiting`` is no help here: for ``socket://`` pyserial reports it as 0 or 1.) A
        ``socket://`` port is read from its socket: pyserial drops the bytes it read just before the
        peer closed (the device's last word, e.g. its 'busy' NACK).
        """
        sock = getattr(self.port, "_socket", None)
        if isinstance(sock, socket.socket):
            return self._read_socket(sock, max_bytes, timeout)
        try:
            self._timeout(timeout)
            first = self.port.read(1)
            if not first:
                return b""
            self._timeout(0)
            return first + self.port.read(max_bytes - 1)
        except (serial.SerialException, OSError) as exc:
            raise DisconnectedError(f"read from {self.url} failed: {exc}") from exc

    def _read_socket(self, sock: socket.socket, max_bytes: int, timeout: float) -> bytes:
        try:
            if not select.select([sock], [], [], timeout)[0]:
                return b""
            data = sock.recv(max_bytes)
        except (OSError, ValueError) as exc:  # ValueError: the socket was closed meanwhile
            raise DisconnectedError(f"read from {self.url} failed: {exc}") from exc
        if not data:
            raise DisconnectedError(f"read from {self.url} failed: the device closed the connection")
        return data

    def close(self) -> None:
        self.port.close()


NETWORK_SCHEMES = ("socket", "rfc2217")


def _check_network_url(url: str) -> None:
    """``socket://HOST:PORT`` and ``rfc2217://HOST:PORT`` need a port 0..65535 (pyserial's own
    complaint names none)."""
    parts = urlsplit(url)
    if parts.scheme.lower() not in NETWORK_SCHEMES:
        return
    try:
        port = parts.port
    except ValueError as exc:
        raise ConfigError(f"{url!r}: the port must be a number 0..65535 ({exc})") from exc
    if port is None:
        raise ConfigError(f"{url!r} names no port: use {parts.scheme}://HOST:PORT")


def split_frame_chunk(url: str) -> tuple[str, int | None]:
    """``url`` without its ``frame_chunk`` option, and the chunk size that option asks for (None:
    not given); ConfigError for a value that is not one size in 256..131072."""
    parts = urlsplit(url)
    pairs = parse_qsl(parts.query, keep_blank_values=True)
    values = [v for k, v in pairs if k == FRAME_CHUNK_OPTION]
    if not values:
        return url, None
    if len(values) > 1 or not values[0].isdigit() or not MIN_FRAME_CHUNK <= int(values[0]) <= MAX_FRAME_CHUNK:
        raise ConfigError(f"{url!r}: {FRAME_CHUNK_OPTION} must be one size in {MIN_FRAME_CHUNK}..{MAX_FRAME_CHUNK} "
                          f"bytes, got {', '.join(values)}")
    rest = urlencode([(k, v) for k, v in pairs if k != FRAME_CHUNK_OPTION])
    return urlunsplit(parts._replace(query=rest)), int(values[0])


def open_transport(url: str, timeout: float) -> SerialTransport:
    _check_network_url(url)
    port_url, frame_chunk = split_frame_chunk(url)
    local = "://" not in port_url  # a device path: locked against a second host on this machine
    try:
        port = serial.serial_for_url(port_url, baudrate=921600, timeout=timeout, write_timeout=max(timeout, 5.0),
                                     **({"exclusive": True} if local else {}))
    except serial.SerialException as exc:
        if local and "exclusively lock" in str(exc):
            raise TransportError(f"{url}: in use by another host (another program has the port open)") from exc
        raise TransportError(f"cannot open {url}: {exc}") from exc
    except (OSError, ValueError) as exc:
        raise TransportError(f"cannot open {url}: {exc}") from exc
    except Exception as exc:  # pyserial's URL handlers raise KeyError, TypeError, ...
        raise TransportError(f"cannot open {url}: {type(exc).__name__}: {exc}") from exc
    return SerialTransport(port, url, frame_chunk)


def discover() -> list["DeviceEntry"]:
    """Serial ports whose USB VID:PID is a camera's (pyserial's port list), and the simulators this
    user serves on this machine over TCP or a pty (``announced``)."""
    from serial.tools import list_ports

    from . import announced

    from ..discovery import DeviceEntry

    entries = []
    for port in sorted(list_ports.comports(), key=lambda p: p.device):
        if port.vid is None or (port.vid, port.pid) not in CAMERA_IDS:
            continue
        entries.append(DeviceEntry(port.device, port.serial_number, port.product, "serial",
                                   location=port.location or port.hwid))
    return entries + announced.discover()
