"""The link layer, written once for every transport: request ids, retries, timeouts, reader thread.

A reader thread feeds the shared protocol decoder; replies wake the request waiting on their
request id, frame messages go to a listener (the frame assembler). Timeouts are float seconds on
the monotonic clock. A retry carries FLAG_RESEND so the device replays instead of re-applying.
"""
from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field
from typing import Callable

from stereocam.protocol import messages as m
from stereocam.protocol.errors import (CONFIG_REFUSALS, CameraTimeoutError, ConfigRefused, DeviceError,
                                      DisconnectedError, LinkFailedError, ProtocolError, StereoCamError,
                                      TransportError)
from stereocam.protocol.framing import FLAG_RESEND, HOST_MESSAGE_TIMEOUT, Decoder, Packet
from stereocam.protocol.params import BY_ID

from .arguments import timeout_arg
from .transports.base import Transport

_log = logging.getLogger(__name__)

READ_CHUNK = 1 << 20


@dataclass(frozen=True)
class LinkStats:
    """A snapshot of a link's counters (``Link.stats``)."""

    requests: int = 0
    retries: int = 0
    timeouts: int = 0
    stray_replies: int = 0  # replies nobody waited for (late answers to timed-out requests, stale ones)
    undecodable: int = 0  # packets with a valid CRC but an unknown type or malformed payload


class _LinkCounters:
    """The link's counters, incremented from any thread (user, heartbeat, repair, reader) under one lock."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._values = dict.fromkeys(LinkStats.__dataclass_fields__, 0)

    def add(self, name: str, n: int = 1) -> None:
        with self._lock:
            self._values[name] += n

    def snapshot(self) -> LinkStats:
        with self._lock:
            return LinkStats(**self._values)


@dataclass
class _Pending:
    expect: int
    event: threading.Event = field(default_factory=threading.Event)
    reply: m.Message | None = None
    error: StereoCamError | None = None


def _answers(pending: _Pending, msg_type: int, msg: m.Message | None) -> bool:
    """Whether a reply with this request id answers ``pending`` (request ids repeat across sessions)."""
    if msg_type == m.MsgType.NACK:
        return not isinstance(msg, m.Nack) or msg.request_type == pending.expect & ~m.REPLY_BIT
    return msg_type == pending.expect


class Link:
    """Request/reply over a Transport, plus a stream of unsolicited device messages."""

    def __init__(self, transport: Transport, *, timeout: float = 1.0, retries: int = 2,
                 on_event: Callable[[m.Message], None] | None = None, first_request_id: int = 1):
        self.transport = transport
        self.timeout = timeout_arg(timeout)
        self.retries = retries
        self.decoder = Decoder(message_timeout=HOST_MESSAGE_TIMEOUT)
        self._counters = _LinkCounters()
        self._on_event = on_event
        self._lock = threading.Lock()
        self._write_lock = threading.Lock()
        self._pending: dict[int, _Pending] = {}
        self._next_id = first_request_id
        self._closed = threading.Event()
        self.error: StereoCamError | None = None  # why the link died, once it has
        self._reader = threading.Thread(target=self._read_loop, name="stereocam-link", daemon=True)
        self._reader.start()

    @property
    def stats(self) -> LinkStats:
        """The counters so far, read consistently (several threads increment them)."""
        return self._counters.snapshot()

    # -- requests -------------------------------------------------------------------------------
    def _allocate_id(self) -> int:
        with self._lock:
            rid = self._next_id
            self._next_id = self._next_id % 0xFFFF + 1  # 1..65535, wraps and skips 0
            return rid

    def _retry(self, msg: m.Message, rid: int, attempt: int, retries: int, why: str) -> None:
        self._counters.add("retries")
        _log.info("%s (request id %d): %s; resending (try %d of %d)", type(msg).__name__, rid, why, attempt + 2,
                  retries + 1)

    def request(self, msg: m.Message, timeout: float | None = None, retries: int | None = None) -> m.Message:
        """Send ``msg``, return the device's reply; DeviceError on NACK, CameraTimeoutError after retries."""
        timeout = self.timeout if timeout is None else timeout_arg(timeout)
        retries = self.retries if retries is None else retries
        self.check_alive()
        rid = self._allocate_id()
        pending = _Pending(m.reply_type(msg.TYPE))
        with self._lock:
            self._pending[rid] = pending
        self._counters.add("requests")
        try:
            for attempt in range(retries + 1):
                try:
                    self._write(m.encode(msg, rid, FLAG_RESEND if attempt else 0))
                except CameraTimeoutError:  # the device did not take the bytes in time: one try spent
                    if attempt < retries:
                        self._retry(msg, rid, attempt, retries, "the device did not take the request in time")
                    continue
                if pending.event.wait(timeout):
                    break
                self.check_alive()
                if attempt < retries:
                    self._retry(msg, rid, attempt, retries, f"no reply in {timeout:.3g} s")
            else:
                self._counters.add("timeouts")
                raise CameraTimeoutError(f"no reply to {type(msg).__name__} (request id {rid}) after "
                                         f"{retries + 1} tries of {timeout:.3g} s")
        finally:
            with self._lock:
                self._pending.pop(rid, None)
        if pending.error is not None:
            raise pending.error
        assert pending.reply is not None
        return pending.reply

    def _write(self, data: bytes) -> None:
        """A write timeout (the device is busy, not gone) is the caller's to retry; any other
        failure ends the link."""
        with self._write_lock:
            try:
                self.transport.write(data)
            except CameraTimeoutError:
                raise
            except StereoCamError as exc:
                self._die(exc)
                raise
            except OSError as exc:
                err = DisconnectedError(f"write to {self.transport.url} failed: {exc}")
                self._die(err)
                raise err from exc

    def check_alive(self) -> None:
        if self.error is not None:
            raise self.error
        if self._closed.is_set():
            raise TransportError("link closed")

    # -- reader ---------------------------------------------------------------------------------
    def _read_loop(self) -> None:
        """Any failure here ends the link with a typed error: waiting requests fail at once,
        later calls raise it, and ``Camera(auto_reconnect=True)`` reconnects on it."""
        while not self._closed.is_set():
            try:
                data = self.transport.read(READ_CHUNK, 0.05)
                for packet in self.decoder.feed(data) if data else self.decoder.expire():
                    self._dispatch(packet)
            except StereoCamError as exc:
                self._die(exc)
                return
            except OSError as exc:
                self._die(DisconnectedError(f"read from {self.transport.url} failed: {exc}"))
                return
            except Exception as exc:  # a bug or MemoryError must not leave a zombie link
                self.fail(exc)
                return

    def fail(self, exc: BaseException) -> None:
        """End the link because a background thread serving it failed with ``exc``."""
        err = LinkFailedError(f"link to {self.transport.url} failed in a background thread: "
                              f"{type(exc).__name__}: {exc}")
        err.__cause__ = exc
        self._die(err)

    def _dispatch(self, packet: Packet) -> None:
        try:
            msg: m.Message | None = m.decode_packet(packet)
            bad = None
        except ProtocolError as exc:
            self._counters.add("undecodable")
            msg, bad = None, exc
        if isinstance(msg, m.Nack) and packet.request_id == 0:  # the device refuses this link (SPEC §9: busy)
            self._die(DisconnectedError(f"{self.transport.url}: in use by another host: the device refused this "
                                         f"link: {msg.message}"))
            return
        if packet.msg_type & m.REPLY_BIT:
            with self._lock:
                pending = self._pending.get(packet.request_id)
            if pending is None or pending.event.is_set() or not _answers(pending, packet.msg_type, msg):
                # nobody waits for it, or it answers another request that had this id (a late reply
                # from before a timeout, or one left in a pty by an earlier session): not this one's
                self._counters.add("stray_replies")
                return
            if bad is not None:  # the answer came but cannot be read: fail now, do not wait
                pending.error = bad
            elif isinstance(msg, m.Nack):
                param = BY_ID[msg.param_id].name if msg.param_id in BY_ID else None
                refused = (ConfigRefused if msg.request_type == m.MsgType.SET_CONFIG and msg.code in CONFIG_REFUSALS
                           else DeviceError)
                pending.error = refused(msg.code, msg.message, param, msg.request_type)
            else:
                pending.reply = msg
            pending.event.set()
        elif msg is not None and self._on_event is not None:
            self._on_event(msg)

    def _die(self, error: StereoCamError) -> None:
        if self.error is None:
            self.error = error
        with self._lock:
            waiting = list(self._pending.values())
        for p in waiting:
            if not p.event.is_set():  # the first error ends the link; a later one (a hang-up) is not news
                p.error = self.error
                p.event.set()

    @property
    def alive(self) -> bool:
        return self.error is None and not self._closed.is_set()

    def close(self) -> None:
        if self._closed.is_set():
            return
        self._closed.set()
        if threading.current_thread() is not self._reader:
            self._reader.join(timeout=2)
        self.transport.close()
