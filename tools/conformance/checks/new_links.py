"""A new host link (SPEC §9): the first-frame deadline, and the refusal a second TCP client hears."""
from __future__ import annotations

import socket
import time

from stereocam.protocol import messages as m
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.framing import Decoder
from stereocam.protocol.params import BY_NAME

from ..budget import budget
from ..context import Context
from ..registry import check
from ..results import CheckFailed, CheckSkipped, expect
from ..wire import WireSession, describe_nack

FIRST_FRAME_S = 3.0  # SPEC §9: a new link is given 3 s (at most 3.5 s) to speak
QUIET_BEFORE_SPEAKING_S = 2.7  # silent this long, a new link must still be served
LATEST_DROP_S = 3.5
SLOT_WAIT_S = 2.0  # SPEC §9: a second client waits up to this for the host to leave


def _tcp_address(url: str) -> tuple[str, int] | None:
    """(host, port) of a TCP camera URL (socket://host:port), else None."""
    if not url.startswith("socket://"):
        return None
    host, _, port = url.removeprefix("socket://").rpartition(":")
    return host, int(port)


def _fresh_link(ctx: Context) -> WireSession:
    """Close the suite's link and open a new one that has not spoken yet (it becomes the suite's)."""
    old = ctx.s
    old.close()
    fresh = WireSession.open(ctx.url, old.timeout)
    fresh.violations = old.violations
    ctx.s = fresh
    ctx.reconnects += 1
    return fresh


@check("link.first_frame_deadline", "R-9-3")
def first_frame_deadline(ctx: Context) -> str:
    """SPEC §9, over TCP (where a link is a connection; a pty or USB host attaches with its first
    bytes): a new link silent for 2.7 s is still served (the deadline is 3 s, not less); a link that
    never speaks is closed within 3.5 s (3 s, not twice the heartbeat timeout)."""
    if _tcp_address(ctx.url) is None:
        raise CheckSkipped("a new link's deadline is a TCP notion (the URL is not socket://)")
    s = _fresh_link(ctx)
    time.sleep(QUIET_BEFORE_SPEAKING_S)
    expect(s.alive, f"a new link was dropped within {QUIET_BEFORE_SPEAKING_S} s, before it spoke (the deadline is "
                    f"{FIRST_FRAME_S} s)")
    r = s.exchange(m.GetInfo())
    expect(isinstance(r, m.Info), f"GET_INFO on a new link after {QUIET_BEFORE_SPEAKING_S} s of silence: {r!r}")
    silent = _fresh_link(ctx)
    t0 = time.monotonic()
    allowed = budget(LATEST_DROP_S)
    while silent.alive and time.monotonic() - t0 < allowed:
        time.sleep(0.02)
    took = time.monotonic() - t0
    closed = not silent.alive
    ctx.reconnect()
    expect(closed, f"a new TCP link that never spoke is still open after {allowed:.3g} s (the deadline is "
                   f"{FIRST_FRAME_S} s, not twice the heartbeat timeout)")
    expect(took >= QUIET_BEFORE_SPEAKING_S, f"a silent new link was closed after {took:.2f} s, before {FIRST_FRAME_S} s")
    return f"served after {QUIET_BEFORE_SPEAKING_S} s of silence; a silent TCP link closed after {took:.2f} s"


@check("link.second_client", "R-6-1", "R-9-4")
def second_client(ctx: Context) -> str:
    """SPEC §6, §9: while the suite holds the link, a second TCP client gets one NACK (request id 0,
    request_type 0, BAD_STATE, param 0) and is closed; the SET_CONFIG it sent is not executed."""
    address = _tcp_address(ctx.url)
    if address is None:
        raise CheckSkipped("a second client is a TCP notion (the URL is not socket://)")
    ctx.require_params("gain")
    gain = BY_NAME["gain"]
    before = ctx.config()
    other = gain.lo if before["gain"] != gain.lo else gain.lo + 1
    decoder = Decoder()
    packets = []
    with socket.create_connection(address, timeout=2.0) as sock:
        sock.sendall(m.encode(m.SetConfig({gain.pid: other}), 1))
        deadline = time.monotonic() + budget(SLOT_WAIT_S + 1.5)
        while time.monotonic() < deadline:
            ctx.s.call(m.Heartbeat())  # the suite's link stays busy: the device must not hand it over
            sock.settimeout(0.2)
            try:
                data = sock.recv(1 << 16)
            except socket.timeout:
                continue
            except OSError:
                break
            if not data:
                break
            packets += decoder.feed(data)
        else:
            raise CheckFailed(f"the second client's connection is still open after {budget(SLOT_WAIT_S + 1.5):.3g} s")
    expect(len(packets) == 1, f"the second client received {len(packets)} messages, expected one NACK")
    nack = m.decode_packet(packets[0])
    expect(isinstance(nack, m.Nack), f"the second client received {nack!r}, expected a NACK")
    assert isinstance(nack, m.Nack)
    expect((packets[0].request_id, nack.request_type, nack.code, nack.param_id) == (0, 0, ErrorCode.BAD_STATE, 0),
           f"the second client's NACK: request id {packets[0].request_id}, request_type {nack.request_type}, "
           f"{describe_nack(nack)}; expected request id "
           "0, request_type 0, BAD_STATE, param 0")
    expect(ctx.config()["gain"] == before["gain"], "the refused second client's SET_CONFIG was executed")
    return f"second client refused: {describe_nack(nack)}, its SET_CONFIG not executed"
