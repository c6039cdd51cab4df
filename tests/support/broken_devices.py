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
from typing import Callable

from stereocam.protocol import messages as m
from stereocam.protocol.framing import FLAG_RESEND, Decoder, Packet, encode_frame
from stereocam.protocol.params import BY_ID, BY_NAME, Param

Rewrite = Callable[[Packet], Packet]
REQUEST_MAX = m.MAX_CALIB_CHUNK + 64  # the largest request a host sends


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
    return v


def without_capabilities(bits: int) -> Rewrite:
    """Device-to-host: INFO no longer advertises ``bits`` (a unit built without those features)."""
    def rewrite(p: Packet) -> Packet:
        if p.msg_type != m.MsgType.INFO:
            return p
        info = m.Info.unpack(p.payload)
        return Packet(p.msg_type, p.request_id, p.flags,
                      dataclasses.replace(info, capabilities=info.capabilities & ~bits).pack())
    return rewrite


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

    def __init__(self, upstream_url: str, rewrite: Rewrite, to_host: Rewrite | None = None):
        host, port = upstream_url.removeprefix("socket://").rsplit(":", 1)
        self.upstream = (host, int(port))
        self.rewrite = rewrite
        self.to_host = to_host
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
        decoder = Decoder(max_payload=REQUEST_MAX)
        with src, dst:
            while data := _recv(src, self._stop):
                for p in decoder.feed(data):
                    q = self.rewrite(p)
                    dst.sendall(encode_frame(q.msg_type, q.request_id, q.payload, q.flags))

    def _to_host(self, src: socket.socket, dst: socket.socket) -> None:
        decoder = Decoder()
        try:
            while data := _recv(src, self._stop):
                for p in decoder.feed(data):
                    q = self.to_host(p)  # type: ignore[misc]
                    dst.sendall(encode_frame(q.msg_type, q.request_id, q.payload, q.flags))
        except OSError:
            pass

    def _pump(self, src: socket.socket, dst: socket.socket) -> None:
        try:
            while data := _recv(src, self._stop):
                dst.sendall(data)
        except OSError:
            pass

    def close(self) -> None:
        self._stop.set()
        self._server.close()
        for t in self._threads:
            t.join(timeout=2)

    def __enter__(self) -> "RewritingProxy":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _recv(sock: socket.socket, stop: threading.Event) -> bytes:
    """The next bytes from ``sock``; b"" when it closed or the proxy stops."""
    sock.settimeout(0.1)
    while not stop.is_set():
        try:
            return sock.recv(1 << 16)
        except socket.timeout:
            continue
        except OSError:
            return b""
    return b""
