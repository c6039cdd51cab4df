"""Hostile bytes between commands (SPEC §2, §3): garbage, corrupt frames, foreign versions, header
extensions and headers announcing large payloads must not stop the device answering in time."""
from __future__ import annotations

import contextlib
import random
import struct
import time
import zlib

from stereocam.protocol import messages as m
from stereocam.protocol.errors import DisconnectedError, StereoCamError
from stereocam.protocol.framing import DEVICE_MESSAGE_TIMEOUT, FLAG_RESEND, MAGIC, header_crc
from stereocam.protocol.params import BY_NAME, TriggerMode

from ..budget import budget
from ..context import Context
from ..registry import check
from ..results import CheckFailed, expect

GARBAGE_BYTES = 4096
QUIET_S = 0.3  # how long the suite waits to be sure a dropped frame got no answer
# a stalled header may cost the device at most the SPEC's message timeout (§3.1), plus a second for
# the suite's resend cadence and a loaded link, before it answers again
LARGE_LENGTH_BUDGET_S = DEVICE_MESSAGE_TIMEOUT + 1.0


def header(msg_type: int, rid: int, payload_len: int, *, major: int = 1, minor: int = 1, header_len: int = 20,
           flags: int = 0) -> bytes:
    """A 20-byte header with a valid CRC, whatever its fields claim."""
    head = struct.pack("<4sBBBBHHIH", MAGIC, major, minor, header_len, flags, msg_type, rid, payload_len, 0)
    return head + struct.pack("<H", header_crc(head))


def frame(msg_type: int, rid: int, payload: bytes = b"", *, major: int = 1, minor: int = 1, extension: bytes = b"") -> bytes:
    """A complete frame, optionally of another version or with a header extension (SPEC §2)."""
    body = extension + payload
    return header(msg_type, rid, len(payload), major=major, minor=minor, header_len=20 + len(extension)) + body + \
        struct.pack("<I", zlib.crc32(body))


def _answers_info(ctx: Context, timeout: float | None = None) -> float:
    """Seconds the device took to answer a GET_INFO (must be within the deadline)."""
    t0 = time.monotonic()
    r = ctx.s.exchange(m.GetInfo(), timeout)
    expect(isinstance(r, m.Info), f"GET_INFO answered {r!r}")
    return time.monotonic() - t0


def _no_reply(ctx: Context, rid: int) -> bool:
    try:
        ctx.s.wait_reply(rid, QUIET_S)
    except TimeoutError:
        return True
    return False


@check("link.garbage", "R-3-1", "R-3.1-1")
def garbage(ctx: Context) -> str:
    """Random bytes and frames with a bad header or payload CRC are dropped and counted; the device
    executes none of them and answers the next request in time."""
    before_cfg, before = ctx.config(), ctx.status()
    junk = random.Random(8).randbytes(GARBAGE_BYTES).replace(MAGIC, b"STOX")
    ctx.s.send_bytes(junk)
    took = _answers_info(ctx)
    gain = BY_NAME["gain"]
    bad_payload = bytearray(m.encode(m.SetConfig({gain.pid: gain.hi}), ctx.s.new_id()))
    bad_payload[-1] ^= 0xFF  # payload CRC
    bad_head = bytearray(m.encode(m.Start(), ctx.s.new_id()))
    bad_head[10] ^= 0x01  # request id changed, header CRC not
    ctx.s.send_bytes(bytes(bad_payload) + bytes(bad_head))
    took = max(took, _answers_info(ctx))
    expect(ctx.config() == before_cfg, "a frame with a bad payload CRC was executed")
    after = ctx.status()
    expect(not after.streaming, "a frame with a bad header CRC was executed (START)")
    d = {k: after.counters[k] - before.counters[k]
         for k in ("rx_garbage_bytes", "rx_header_crc_errors", "rx_payload_crc_errors")}
    expect(d["rx_garbage_bytes"] >= GARBAGE_BYTES - 3, f"rx_garbage_bytes +{d['rx_garbage_bytes']} for "
                                                       f"{GARBAGE_BYTES} garbage bytes")
    expect(d["rx_header_crc_errors"] >= 1 and d["rx_payload_crc_errors"] >= 1, f"CRC errors not counted: {d}")
    return f"answered within {took * 1e3:.0f} ms; counted {d}"


@check("link.versions_and_extensions", "R-2-1", "R-2-2", "R-3-1", "R-11-1", "R-11.2-1")
def versions(ctx: Context) -> str:
    """Any minor and a header extension (header_len 21..64) accepted; another major and
    header_len outside 20..64 dropped without an answer, counted."""
    s = ctx.s
    before = s.call(m.Heartbeat())
    rid = s.new_id()
    s.expect_reply(rid, m.MsgType.GET_INFO)
    s.send_bytes(frame(m.MsgType.GET_INFO, rid, minor=9, extension=bytes(range(8))))
    expect(isinstance(s.wait_reply(rid).message, m.Info), "GET_INFO of minor 9 with an 8-byte header extension")
    for what, data in (("major 2", frame(m.MsgType.GET_INFO, rid := s.new_id(), major=2)),
                       ("header_len 19", header(m.MsgType.GET_INFO, rid := s.new_id(), 0, header_len=19) + bytes(4)),
                       ("header_len 65", header(m.MsgType.GET_INFO, rid := s.new_id(), 0, header_len=65) + bytes(49))):
        s.expect_reply(rid, m.MsgType.GET_INFO)
        s.send_bytes(data)
        expect(_no_reply(ctx, rid), f"a frame of {what} was answered")
    after = s.call(m.Heartbeat())
    assert isinstance(before, m.Status) and isinstance(after, m.Status)
    dv = after.counters["rx_unsupported_version"] - before.counters["rx_unsupported_version"]
    dh = after.counters["rx_header_crc_errors"] - before.counters["rx_header_crc_errors"]
    expect(dv >= 1 and dh >= 2, f"rx_unsupported_version +{dv}, rx_header_crc_errors +{dh} (bad header_len)")
    return "minor 9 + extension answered; major 2, header_len 19 and 65 dropped and counted"


@check("link.oversize_header", "R-3-2")
def oversize(ctx: Context) -> str:
    """A CRC-valid header announcing more than INFO.max_payload is rejected from the header alone
    (never buffered): the next request is answered in time, rx_oversize counts it."""
    before = ctx.status()
    for n in (ctx.info.max_payload + 1, 0xFFFFFFFF):
        ctx.s.send_bytes(header(m.MsgType.SET_CONFIG, ctx.s.new_id(), n))
        took = _answers_info(ctx)
    d = ctx.status().counters["rx_oversize"] - before.counters["rx_oversize"]
    expect(d >= 2, f"rx_oversize +{d} for two oversize headers")
    return f"answered within {took * 1e3:.0f} ms after headers of {ctx.info.max_payload + 1} and 2^32-1 bytes"


@check("link.large_length_header", "R-3-3")
def large_length(ctx: Context) -> str:
    """A CRC-valid header announcing the largest legal payload, then nothing: the device must not
    wait for that payload forever (issue 9): it answers a following GET_INFO (resent every
    deadline) within LARGE_LENGTH_BUDGET_S. The suite then completes the announced frame with
    filler so the device recovers either way."""
    s = ctx.s
    n = ctx.info.max_payload
    s.send_bytes(header(m.MsgType.SET_CONFIG, s.new_id(), n))
    t0 = time.monotonic()
    rid = s.send(m.GetInfo())
    answered = None
    allowed = budget(LARGE_LENGTH_BUDGET_S)
    try:
        while answered is None and time.monotonic() - t0 < allowed:
            try:
                answered = s.wait_reply(rid, min(s.timeout, allowed - (time.monotonic() - t0)))
            except TimeoutError:
                s.send(m.GetInfo(), rid, FLAG_RESEND)
    finally:
        if answered is None:
            s.send_bytes(bytes(n + 4))  # completes the announced frame (bad CRC): the decoder resynchronises
    took = time.monotonic() - t0
    expect(answered is not None,
           f"DEAF: no answer within {allowed:.3g} s after a CRC-valid header announcing {n} payload bytes "
           f"(the device waits for the payload; it must bound that wait, issue 9)")
    return f"answered within {took * 1e3:.0f} ms after a header announcing {n} bytes"


STRAY_HEADERS = 8  # chained stray headers: T in all for a decoder timing by arrival, 8 T for one timing by rescan
STRAY_PAYLOAD = 1024  # what each announces: more than every byte sent behind them, within any max_payload
MESSAGE_TIMEOUT_BUDGET_S = DEVICE_MESSAGE_TIMEOUT + 1.0


@check("link.message_timeout", "R-3-4", "R-3-5")
def message_timeout(ctx: Context) -> str:
    """SPEC §3: CRC-valid headers announcing payloads that never come, sent back to back with a
    GET_INFO behind them: each header's wait runs from its own arrival, so the GET_INFO is answered
    within T (not T per header), and rx_message_timeouts counts the abandoned frames."""
    s = ctx.s
    n = min(STRAY_PAYLOAD, ctx.info.max_payload)
    before = ctx.status()
    rid = s.new_id()
    s.expect_reply(rid, m.MsgType.GET_INFO)
    stray = b"".join(header(m.MsgType.SET_CONFIG, s.new_id(), n) for _ in range(STRAY_HEADERS))
    t0 = time.monotonic()
    s.send_bytes(stray + frame(m.MsgType.GET_INFO, rid))
    allowed = budget(MESSAGE_TIMEOUT_BUDGET_S)
    answered = None
    rule = ("each header's wait must run from its own arrival (T in all), not from when a rescan "
            "reached it")
    try:
        while answered is None and time.monotonic() - t0 < allowed:
            try:  # a device need not poll its decoder while idle: later bytes let it expire the wait
                answered = s.wait_reply(rid, min(0.2, allowed - (time.monotonic() - t0)))
            except TimeoutError:
                s.send(m.GetInfo(), rid, FLAG_RESEND)
    except DisconnectedError as e:  # a receive path stuck that long can trip the link's watchdog
        raise CheckFailed(f"the link dropped ({e}) {time.monotonic() - t0:.3g} s into {STRAY_HEADERS} "
                          f"stray headers announcing {n} bytes each, unanswered: {rule}") from e
    finally:
        if answered is None:
            with contextlib.suppress(StereoCamError):  # completes the frame being waited on: the
                s.send_bytes(bytes(n + 4))  # decoder resynchronises (if the link is still up)
    took = time.monotonic() - t0
    expect(answered is not None,
           f"no answer within {allowed:.3g} s behind {STRAY_HEADERS} stray headers announcing {n} bytes each: "
           + rule)
    counters = ctx.status().counters
    if "rx_message_timeouts" in counters:
        d = counters["rx_message_timeouts"] - before.counters["rx_message_timeouts"]
        expect(d >= 1, f"rx_message_timeouts +{d} after abandoned frames")
    return f"answered after {took * 1e3:.0f} ms behind {STRAY_HEADERS} stray headers (T = {DEVICE_MESSAGE_TIMEOUT} s)"


STRAY_WATCHDOG_MS = 500  # below T + a heartbeat period: a blinded decoder would trip it
STRAY_KEEPALIVE_S = 2.0
STRAY_HEARTBEAT_S = 0.15


@check("link.stray_header_keeps_host", "R-9-1")
def stray_header_keeps_host(ctx: Context) -> str:
    """SPEC §9: a stray header (a CRC-valid header whose payload never comes) while streaming with
    heartbeat_timeout_ms = 500 and heartbeats every 150 ms: the decoder waits up to T (1 s) for the
    payload, but that wait is not silence, so neither the watchdog nor the link timeout fires."""
    ctx.require_params("heartbeat_timeout_ms", "trigger_mode", "fps")
    ctx.apply(heartbeat_timeout_ms=STRAY_WATCHDOG_MS, trigger_mode=int(TriggerMode.FREE_RUN), fps=5)
    before = ctx.status()
    ctx.s.call(m.Start())
    ctx.s.send_bytes(header(m.MsgType.SET_CONFIG, ctx.s.new_id(), min(1024, ctx.info.max_payload)))
    end = time.monotonic() + STRAY_KEEPALIVE_S
    while time.monotonic() < end and ctx.s.alive:
        try:
            ctx.s.send(m.Heartbeat())  # answered late while the decoder waits: not waited for here
        except StereoCamError:
            break
        time.sleep(STRAY_HEARTBEAT_S)
    dropped = not ctx.s.alive
    if dropped:
        ctx.reconnect()
    after = ctx.status()
    ctx.stop()
    d = after.counters["heartbeat_timeouts"] - before.counters["heartbeat_timeouts"]
    expect(not dropped, "the device dropped the link of a host that sent HEARTBEAT every "
                        f"{STRAY_HEARTBEAT_S * 1e3:.0f} ms after one stray header")
    expect(after.streaming and d == 0,
           f"after one stray header the watchdog stopped the stream (streaming={after.streaming}, "
           f"heartbeat_timeouts +{d}) although HEARTBEATs arrived every {STRAY_HEARTBEAT_S * 1e3:.0f} ms "
           f"(heartbeat_timeout_ms={STRAY_WATCHDOG_MS})")
    return (f"streaming on for {STRAY_KEEPALIVE_S:.1f} s after a stray header with heartbeat_timeout_ms="
            f"{STRAY_WATCHDOG_MS}, link kept")
