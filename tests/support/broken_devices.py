"""Deliberately broken devices for the conformance tests, built at the byte level: a real TCP
proxy in front of a served simulator rewrites host-to-device frames with the shared codec, so the
breakage survives any change to the firmware's internals.

Host-to-device bytes are decoded and re-encoded (v1.1, 20-byte header), so what the decoder drops
(garbage, foreign versions, oversize headers) never reaches the device: judge such a device only
on the checks the breakage is about. Device-to-host bytes pass unchanged, or through a rewrite of
their own.
"""
from __future__ import annotations

import dataclasses
import socket
import struct
import threading
import time
from typing import Callable

from stereocam.protocol import messages as m
from stereocam.protocol.framing import FLAG_RESEND, Decoder, Packet, encode_frame
from stereocam.protocol.params import BY_ID, BY_NAME, Param

Rewrite = Callable[[Packet], Packet]
REQUEST_MAX = m.MAX_CALIB_CHUNK + 64  # the largest request a host sends
KEEPALIVE_ID = 0xFFF0  # request id of the HEARTBEATs a proxy sends for a silent host (their replies are dropped)


def unchanged(p: Packet) -> Packet:
    return p


def forget_resend(p: Packet) -> Packet:
    """Clear FLAG_RESEND: the device executes every retried command again."""
    return Packet(p.msg_type, p.request_id, p.flags & ~FLAG_RESEND, p.payload)


def _rewrite_config(p: Packet, change: Callable[[dict[int, int]], dict[int, int]]) -> Packet:
    """A SET_CONFIG with its values passed through ``change``; every other packet as it was."""
    if p.msg_type != m.MsgType.SET_CONFIG:
        return p
    try:
        values = m.SetConfig.unpack(p.payload).values
    except struct.error:  # the malformed lists the suite sends on purpose
        return p
    return Packet(p.msg_type, p.request_id, p.flags, m.SetConfig(change(values)).pack())


def clamp_into_range(p: Packet) -> Packet:
    """Move every out-of-range SET_CONFIG value onto the nearest legal one: the device appears to
    accept values outside the table."""
    return _rewrite_config(p, lambda values: {
        pid: _nearest_legal(BY_ID[pid], v) if pid in BY_ID and BY_ID[pid].check(v) else v for pid, v in values.items()})


def dead_trigger_output(p: Packet) -> Packet:
    """SET_CONFIG reaches the device with ``trigger_output`` forced to 0: a unit that advertises
    the output and answers CONFIG_APPLIED but never drives its line."""
    pid = BY_NAME["trigger_output"].pid
    return _rewrite_config(p, lambda values: {**values, **({pid: 0} if pid in values else {})})


def ignore_params(*names: str) -> Rewrite:
    """SET_CONFIG reaches the device without ``names``: a unit that answers CONFIG_APPLIED to them
    but never applies them (e.g. a post-processing stage it does not run)."""
    pids = {BY_NAME[n].pid for n in names}
    return lambda p: _rewrite_config(p, lambda values: {k: v for k, v in values.items() if k not in pids})


def _nearest_legal(prm: Param, v: int) -> int:
    v = min(max(v, prm.lo), prm.hi)
    if prm.step > 1:
        v -= (v - prm.lo) % prm.step
    if prm.odd and v % 2 == 0:
        v = v + 1 if v < prm.hi else v - 1
    if prm.one_of:
        v = min(prm.one_of, key=lambda legal: abs(legal - v))
    return v


def first_duplicate_wins(p: Packet) -> Packet:
    """SET_CONFIG reaches the device with only the first entry of each id: a device that keeps the
    first value of a duplicated id (SPEC §4.3: the last one is used, every one is checked)."""
    if p.msg_type != m.MsgType.SET_CONFIG or len(p.payload) < 2:
        return p
    try:
        pairs = m.SetConfig.unpack(p.payload).pairs
    except struct.error:
        return p
    first: dict[int, int] = {}
    for pid, value in pairs:
        first.setdefault(pid, value)
    return Packet(p.msg_type, p.request_id, p.flags, m.SetConfig(first).pack())


def commit_what_is_staged(p: Packet) -> Packet:
    """A CALIB_WRITE starting a staging reaches the device announcing only the bytes it carries: a
    device that commits a partly staged body (SPEC §12.4 step 3)."""
    if p.msg_type != m.MsgType.CALIB_WRITE:
        return p
    w = m.CalibWrite.unpack(p.payload)
    if w.offset or w.total <= len(w.data):
        return p
    return Packet(p.msg_type, p.request_id, p.flags, dataclasses.replace(w, total=len(w.data)).pack())


def counting_stop_discards() -> Rewrite:
    """Device-to-host: STATUS counts one frame dropped per STOP answered so far (a device that counts
    the captures a STOP discards as drops, SPEC §4.6)."""
    stops = [0]

    def rewrite(p: Packet) -> Packet:
        if p.msg_type == m.MsgType.STOPPED:
            stops[0] += 1
        if p.msg_type != m.MsgType.STATUS:
            return p
        st = m.Status.unpack(p.payload)
        counters = {**st.counters, "frames_dropped": st.counters["frames_dropped"] + stops[0]}
        return Packet(p.msg_type, p.request_id, p.flags, dataclasses.replace(st, counters=counters).pack())
    return rewrite


def typed_busy_nack(p: Packet) -> Packet:
    """Device-to-host: the NACK refusing a second client names GET_INFO as its request type (SPEC
    §6: it answers no request, request_type 0)."""
    if p.msg_type != m.MsgType.NACK or p.request_id != 0:
        return p
    n = m.Nack.unpack(p.payload)
    return Packet(p.msg_type, p.request_id, p.flags, dataclasses.replace(n, request_type=m.MsgType.GET_INFO).pack())


def generations_restart() -> Rewrite:
    """Device-to-host: after a CALIB_RESTORE the user generations reported start again from 1 (SPEC
    §12.1: they never repeat)."""
    seen, offset = [0], [0]

    def rewrite(p: Packet) -> Packet:
        msg = m.decode_packet(p) if p.msg_type in (m.MsgType.CALIB_RESTORED, m.MsgType.CALIB_COMMITTED,
                                                   m.MsgType.CALIB_DATA) else None
        if isinstance(msg, m.CalibRestored):
            offset[0] = seen[0]
        if not isinstance(msg, (m.CalibCommitted, m.CalibData)) or msg.source != m.CalibSource.USER:
            return p
        seen[0] = max(seen[0], msg.generation)
        return Packet(p.msg_type, p.request_id, p.flags,
                      dataclasses.replace(msg, generation=msg.generation - offset[0]).pack())
    return rewrite


class RescanTimedDecoder(Decoder):
    """A receive path that times a header from when its scan reaches it, not from its arrival (SPEC
    §3): behind a chain of stray headers it waits the message timeout once per header."""

    def __init__(self, **kwargs: object) -> None:
        super().__init__(**kwargs)  # type: ignore[arg-type]
        self._seen: dict[int, float] = {}

    def _timed_out(self, offset: int, now: float | None) -> bool:
        now = time.monotonic() if now is None else now
        since = self._seen.setdefault(offset, now)
        return self.message_timeout is not None and now - since > self.message_timeout


def blinding_decoder() -> Decoder:
    """A receive path that waits up to 1 s for a stray header's payload and holds every frame behind
    it meanwhile, without telling the watchdog (SPEC §9: that wait is not silence)."""
    return Decoder(max_payload=REQUEST_MAX, message_timeout=1.0)


def rescan_timed_decoder() -> Decoder:
    return RescanTimedDecoder(max_payload=REQUEST_MAX, message_timeout=1.0)


class LinkDroppingDecoder(RescanTimedDecoder):
    """The rescan-timed receive path of a unit whose watchdog, once a header has waited past the
    message timeout, drops the link instead of abandoning the frame (the proxy hangs up on both
    sides)."""

    def _timed_out(self, offset: int, now: float | None) -> bool:
        if super()._timed_out(offset, now):
            raise ConnectionAbortedError("receive watchdog: the link is dropped")
        return False


def link_dropping_decoder() -> Decoder:
    return LinkDroppingDecoder(max_payload=REQUEST_MAX, message_timeout=1.0)


GROUPS = {m.Capability.CALIBRATION: range(m.MsgType.CALIB_READ, m.MsgType.CALIB_RESTORE + 1)}
"""SPEC §4.0 capability groups this module can hide (request types)."""
HIDDEN_BASE = 0x3F00  # a hidden request travels as this | its low byte: a type the device does not know


def without_features(bits: int) -> tuple[Rewrite, Rewrite]:
    """(to device, to host) rewrites that make the unit one built without ``bits``, consistently:
    INFO lacks them, the requests of a hidden group are unknown (NACK UNKNOWN_TYPE naming them), and
    without EXTERNAL_TRIGGER ``trigger_mode`` = 2 is refused OUT_OF_RANGE."""
    hidden = {t for bit, types in GROUPS.items() if bits & bit for t in types}
    travelling = {HIDDEN_BASE | (t & 0xFF): t for t in hidden}
    mode = BY_NAME["trigger_mode"].pid

    def to_device(p: Packet) -> Packet:
        if p.msg_type in hidden:
            return Packet(HIDDEN_BASE | (p.msg_type & 0xFF), p.request_id, p.flags, p.payload)
        if bits & m.Capability.EXTERNAL_TRIGGER:
            return _rewrite_config(p, lambda values: {k: (3 if k == mode and v == 2 else v) for k, v in values.items()})
        return p

    info_without = without_capabilities(bits)

    def to_host(p: Packet) -> Packet:
        if p.msg_type == m.MsgType.NACK:
            n = m.Nack.unpack(p.payload)
            if n.request_type in travelling:
                n = dataclasses.replace(n, request_type=travelling[n.request_type])
                return Packet(p.msg_type, p.request_id, p.flags, n.pack())
        return info_without(p)
    return to_device, to_host


def without_capabilities(bits: int) -> Rewrite:
    """Device-to-host: INFO no longer advertises ``bits`` (a unit built without those features)."""
    def rewrite(p: Packet) -> Packet:
        if p.msg_type != m.MsgType.INFO:
            return p
        info = m.Info.unpack(p.payload)
        return Packet(p.msg_type, p.request_id, p.flags,
                      dataclasses.replace(info, capabilities=info.capabilities & ~bits).pack())
    return rewrite


def small_sgm_limit(p: Packet) -> Packet:
    """Device-to-host: INFO says SGM runs up to 640x480 (SPEC §4.1 stage limits) while the device
    still accepts SGM at every format: a limit it does not enforce (§5.2 rule 8)."""
    if p.msg_type != m.MsgType.INFO:
        return p
    info = m.Info.unpack(p.payload)
    return Packet(p.msg_type, p.request_id, p.flags,
                  dataclasses.replace(info, stage_limits=((m.Stage.SEMI_GLOBAL, 640, 480),)).pack())


def stale_slot_report(p: Packet) -> Packet:
    """Device-to-host: UPDATE_STATE names another version in every slot (bookkeeping that says an
    update took when the unit still runs the old image, or the reverse)."""
    if p.msg_type != m.MsgType.UPDATE_STATE:
        return p
    st = m.UpdateState.unpack(p.payload)
    slots = tuple(dataclasses.replace(s, version=s.version + "-stale") for s in st.slots)
    return Packet(p.msg_type, p.request_id, p.flags, dataclasses.replace(st, slots=slots).pack())


class RewritingProxy:
    """Listens on 127.0.0.1; each host connection gets its own connection to ``upstream``."""

    def __init__(self, upstream_url: str, rewrite: Rewrite, to_host: Rewrite | None = None,
                 decoder: Callable[[], Decoder] = lambda: Decoder(max_payload=REQUEST_MAX),
                 speak_for_silent_host: bool = False):
        """``decoder``: the host-to-device receive path; ``speak_for_silent_host``: a host that has
        not spoken for 1 s gets a HEARTBEAT sent for it every second (its replies are dropped)."""
        host, port = upstream_url.removeprefix("socket://").rsplit(":", 1)
        self.upstream = (host, int(port))
        self.rewrite = rewrite
        self.to_host = to_host if to_host is not None or not speak_for_silent_host else unchanged
        self.decoder = decoder
        self.speak_for_silent_host = speak_for_silent_host
        self._server = socket.create_server(("127.0.0.1", 0))
        self.url = f"socket://127.0.0.1:{self._server.getsockname()[1]}"
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._accept, daemon=True)]
        self._threads[0].start()

    def _accept(self) -> None:
        self._server.settimeout(0.1)
        while not self._stop.is_set():
            try:
                host, _ = self._server.accept()
            except (socket.timeout, OSError):
                continue
            device = socket.create_connection(self.upstream)
            back = self._pump if self.to_host is None else self._to_host
            for target, args in ((self._to_device, (host, device)), (back, (device, host))):
                t = threading.Thread(target=target, args=args, daemon=True)
                t.start()
                self._threads.append(t)

    def _to_device(self, src: socket.socket, dst: socket.socket) -> None:
        decoder = self.decoder()
        spoken, last = False, time.monotonic()

        def idle() -> None:
            nonlocal last
            if self.speak_for_silent_host and not spoken and time.monotonic() - last > 1.0:
                dst.sendall(encode_frame(m.MsgType.HEARTBEAT, KEEPALIVE_ID))
                last = time.monotonic()
        with src, dst:  # closed on the way out: both sides see the hang-up
            try:
                while data := _recv(src, self._stop, idle):
                    spoken = True
                    for p in decoder.feed(data):
                        q = self.rewrite(p)
                        dst.sendall(encode_frame(q.msg_type, q.request_id, q.payload, q.flags))
            except OSError:  # a peer gone, or a receive path that drops the link
                pass

    def _to_host(self, src: socket.socket, dst: socket.socket) -> None:
        decoder = Decoder()
        try:
            while data := _recv(src, self._stop):
                for p in decoder.feed(data):
                    if p.request_id == KEEPALIVE_ID and self.speak_for_silent_host:
                        continue
                    q = self.to_host(p)  # type: ignore[misc]
                    dst.sendall(encode_frame(q.msg_type, q.request_id, q.payload, q.flags))
        except OSError:
            pass
        _hang_up(dst)

    def _pump(self, src: socket.socket, dst: socket.socket) -> None:
        try:
            while data := _recv(src, self._stop):
                dst.sendall(data)
        except OSError:
            pass
        _hang_up(dst)

    def close(self) -> None:
        self._stop.set()
        self._server.close()
        for t in self._threads:
            t.join(timeout=2)

    def __enter__(self) -> "RewritingProxy":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _hang_up(sock: socket.socket) -> None:
    """The device side ended: the host sees its connection closed as it would without the proxy."""
    try:
        sock.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass


def _recv(sock: socket.socket, stop: threading.Event, idle: Callable[[], None] = lambda: None) -> bytes:
    """The next bytes from ``sock``; b"" when it closed or the proxy stops. ``idle`` runs every 0.1 s
    without bytes."""
    sock.settimeout(0.1)
    while not stop.is_set():
        try:
            return sock.recv(1 << 16)
        except socket.timeout:
            idle()
            continue
        except OSError:
            return b""
    return b""
