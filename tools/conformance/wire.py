"""The judge's own view of the wire: requests with chosen ids and flags, raw bytes, every reply kept.

The SDK's Link hides what a judge must see (it retries, picks request ids, turns NACKs into
exceptions, drops late replies), so the suite drives the SDK's transport with the shared codec
itself. Nothing is sent that the suite did not ask for: no heartbeat thread, so silence is real.
Every reply and event is checked against the framing rules as it arrives; breaches are kept in
``violations`` for the final check.
"""
from __future__ import annotations

import collections
import threading
import time
from dataclasses import dataclass

from stereocam.protocol import messages as m
from stereocam.protocol.errors import CameraTimeoutError, ErrorCode, ProtocolError, StereoCamError
from stereocam.protocol.framing import FLAG_RESEND, Decoder, Packet, encode_frame
from stereocam.protocol.params import BY_ID
from stereocam.transports import Transport, open_transport

from .captures import CaptureLog

READ_CHUNK = 1 << 20


@dataclass(frozen=True)
class Reply:
    packet: Packet
    message: m.Message | None  # None: the payload did not decode (a violation is recorded)
    events_before: int  # capture messages received before this reply


class WireSession:
    """One host link to the device under test, owned by the suite."""

    def __init__(self, transport: Transport, timeout: float = 1.0):
        self.transport = transport
        self.timeout = timeout
        self.decoder = Decoder()
        self.captures = CaptureLog()
        self.violations: list[str] = []
        self.error: StereoCamError | None = None
        self._next_id = 1
        self._expect: dict[int, int] = {}  # request id -> request type last sent with it
        self._replies: dict[int, collections.deque[Reply]] = collections.defaultdict(collections.deque)
        self._cond = threading.Condition()
        self._closed = threading.Event()
        self._reader = threading.Thread(target=self._read_loop, name="conformance-reader", daemon=True)
        self._reader.start()

    @classmethod
    def open(cls, url: str, timeout: float) -> "WireSession":
        return cls(open_transport(url, timeout), timeout)

    # -- sending --------------------------------------------------------------------------------
    def new_id(self) -> int:
        rid = self._next_id
        self._next_id = self._next_id % 0xFFFF + 1
        return rid

    def send(self, msg: m.Message, rid: int | None = None, flags: int = 0) -> int:
        """Send ``msg`` as request ``rid`` (a fresh id if None) with ``flags``; returns the id."""
        return self.send_frame(msg.TYPE, msg.pack(), rid, flags)

    def send_frame(self, msg_type: int, payload: bytes, rid: int | None = None, flags: int = 0) -> int:
        """Send a request frame of any type (known or not) with any payload; returns the id."""
        rid = self.new_id() if rid is None else rid
        self.expect_reply(rid, msg_type, fresh=not flags & FLAG_RESEND)
        self.send_bytes(encode_frame(msg_type, rid, payload, flags))
        return rid

    def expect_reply(self, rid: int, msg_type: int, fresh: bool = True) -> None:
        """Note that request ``rid`` of ``msg_type`` is on its way (for bytes the suite builds itself);
        ``fresh``: forget late answers to an earlier use of the id."""
        with self._cond:
            if fresh:
                self._replies.pop(rid, None)
            self._expect[rid] = msg_type

    def send_bytes(self, data: bytes) -> None:
        self.check_alive()
        self.transport.write(data)

    # -- receiving ------------------------------------------------------------------------------
    def wait_reply(self, rid: int, timeout: float | None = None) -> Reply:
        """The next reply carrying ``rid``; CameraTimeoutError if none within ``timeout``."""
        timeout = self.timeout if timeout is None else timeout
        deadline = time.monotonic() + timeout
        with self._cond:
            while not self._replies.get(rid):
                left = deadline - time.monotonic()
                if self.error is not None:
                    raise self.error
                if left <= 0:
                    raise CameraTimeoutError(f"no reply to request id {rid} within {timeout:.3g} s")
                self._cond.wait(left)
            return self._replies[rid].popleft()

    def exchange(self, msg: m.Message, timeout: float | None = None) -> m.Message:
        """Send once, return the reply: the expected reply type or a Nack. No retry."""
        reply = self.wait_reply(self.send(msg), timeout)
        if reply.message is None:
            raise ProtocolError(f"undecodable reply 0x{reply.packet.msg_type:04x} to {type(msg).__name__}")
        if not isinstance(reply.message, (m.Nack, m.REPLIES[msg.TYPE])):
            raise ProtocolError(f"{type(reply.message).__name__} in reply to {type(msg).__name__}")
        return reply.message

    def call(self, msg: m.Message, timeout: float | None = None) -> m.Message:
        """Like ``exchange`` but a NACK is an error (RefusedError naming code and parameter)."""
        reply = self.exchange(msg, timeout)
        if isinstance(reply, m.Nack):
            raise RefusedError(reply, type(msg).__name__)
        return reply

    @property
    def alive(self) -> bool:
        return self.error is None and not self._closed.is_set()

    def check_alive(self) -> None:
        if self.error is not None:
            raise self.error

    def _read_loop(self) -> None:
        while not self._closed.is_set():
            try:
                data = self.transport.read(READ_CHUNK, 0.05)
            except StereoCamError as exc:
                with self._cond:
                    self.error = exc
                    self._cond.notify_all()
                return
            for packet in self.decoder.feed(data) if data else ():
                self._dispatch(packet)

    def _dispatch(self, packet: Packet) -> None:
        now = time.monotonic()
        try:
            msg: m.Message | None = m.decode_packet(packet)
        except ProtocolError as exc:
            msg = None
            self.violations.append(f"undecodable message from the device: {exc}")
        if packet.flags:
            self.violations.append(f"device message 0x{packet.msg_type:04x} with flags 0x{packet.flags:02x} (must be 0)")
        if packet.msg_type & m.REPLY_BIT:
            self._reply(packet, msg)
        elif packet.msg_type & m.EVENT_BIT:
            if packet.request_id:
                self.violations.append(f"event 0x{packet.msg_type:04x} with request id {packet.request_id} (must be 0)")
            if msg is not None:
                self.captures.on_message(msg, now)
        else:
            self.violations.append(f"device sent request type 0x{packet.msg_type:04x}")

    def _reply(self, packet: Packet, msg: m.Message | None) -> None:
        with self._cond:
            sent = self._expect.get(packet.request_id)
            if sent is None:
                self.violations.append(f"reply 0x{packet.msg_type:04x} to request id {packet.request_id}, never used")
            elif packet.msg_type != m.reply_type(sent) and packet.msg_type != m.MsgType.NACK:
                self.violations.append(f"reply 0x{packet.msg_type:04x} to a request of type 0x{sent:04x}")
            elif isinstance(msg, m.Nack) and msg.request_type != sent:
                self.violations.append(f"NACK names request type 0x{msg.request_type:04x}, the request was 0x{sent:04x}")
            self._replies[packet.request_id].append(Reply(packet, msg, self.captures.messages))
            self._cond.notify_all()

    def close(self) -> None:
        self._closed.set()
        if threading.current_thread() is not self._reader:
            self._reader.join(timeout=2)
        self.transport.close()


class RefusedError(StereoCamError):
    """The device NACKed a request the suite expected it to execute."""

    def __init__(self, nack: m.Nack, request: str):
        self.nack = nack
        super().__init__(f"{request} refused: {describe_nack(nack)}")


def describe_nack(nack: m.Nack) -> str:
    try:
        code = ErrorCode(nack.code).name
    except ValueError:
        code = f"code {nack.code}"
    param = f" param {nack.param_id}" + (f" ({BY_ID[nack.param_id].name})" if nack.param_id in BY_ID else "") \
        if nack.param_id else ""
    return f"NACK {code}{param}: {nack.message!r}"
