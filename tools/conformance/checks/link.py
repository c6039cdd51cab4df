"""Link rules: the heartbeat watchdog stops a stream when the host goes silent; a RESEND is
answered from the replay cache, never executed twice (SPEC §7, §9)."""
from __future__ import annotations

import time

from stereocam.protocol import messages as m
from stereocam.protocol.framing import FLAG_RESEND
from stereocam.protocol.params import BY_NAME, TriggerMode

from ..context import Context
from ..registry import check
from ..results import expect

WATCHDOG_MS = 600
KEPT_ALIVE_S = 1.0
CHECK_SLACK_S = 0.35  # the device checks at least every 50 ms (ref) and between captures


@check("link.watchdog", "R-9-2")
def watchdog(ctx: Context) -> str:
    """Heartbeats keep a stream alive; silence longer than heartbeat_timeout_ms stops it (as STOP),
    counted in heartbeat_timeouts, and no capture begins after that."""
    ctx.require_params("heartbeat_timeout_ms", "trigger_mode", "fps")
    ctx.apply(heartbeat_timeout_ms=WATCHDOG_MS, trigger_mode=int(TriggerMode.FREE_RUN), fps=10)
    before = ctx.status()
    ctx.s.captures.clear()
    ctx.s.call(m.Start())
    end = time.monotonic() + KEPT_ALIVE_S
    while time.monotonic() < end:
        time.sleep(WATCHDOG_MS / 4000)
        expect(ctx.status().streaming, f"stream stopped although the host sent HEARTBEAT every {WATCHDOG_MS / 4:.0f} ms")
    silent_from = time.monotonic()
    time.sleep(WATCHDOG_MS / 1000 + CHECK_SLACK_S + 0.2)
    caps = ctx.s.captures.snapshot()
    if not ctx.s.alive:  # the device may also drop a silent host's link; the counter still tells
        ctx.reconnect()
    after = ctx.status()
    expect(not after.streaming, f"still streaming after {time.monotonic() - silent_from:.2f} s of host silence "
                                f"with heartbeat_timeout_ms={WATCHDOG_MS}")
    d = after.counters["heartbeat_timeouts"] - before.counters["heartbeat_timeouts"]
    expect(d == 1, f"heartbeat_timeouts +{d}, expected +1")
    ctx.note_captures(caps)
    late = [c.sequence for c in caps if c.received > silent_from + WATCHDOG_MS / 1000 + CHECK_SLACK_S]
    expect(not late, f"captures {late} began more than {WATCHDOG_MS} ms + {CHECK_SLACK_S * 1e3:.0f} ms into the silence")
    expect(caps, "no capture while the stream was kept alive")
    return f"kept alive {KEPT_ALIVE_S:.1f} s by heartbeats ({len(caps)} captures), stopped by {WATCHDOG_MS} ms of silence"


@check("link.resend_replayed", "R-7-1", "R-7-2")
def resend_replayed(ctx: Context) -> str:
    """A RESEND of an answered request gets the cached reply, byte for byte, and is not executed:
    TIME keeps the first time, a SET_CONFIG does not undo a later change; without RESEND the
    same id executes anew; a RESEND of an id never seen executes."""
    s = ctx.s
    before = ctx.status()
    rid = s.send(m.TimeSync())
    first = s.wait_reply(rid)
    time.sleep(0.02)
    s.send(m.TimeSync(), rid, FLAG_RESEND)
    again = s.wait_reply(rid)
    expect(again.packet == first.packet, f"TIME_SYNC resent: {again.message!r}, first answer was {first.message!r} "
                                         "(executed twice)")
    s.send(m.TimeSync(), rid)
    fresh = s.wait_reply(rid).message
    assert isinstance(fresh, m.Time) and isinstance(first.message, m.Time)
    expect(fresh.device_time_us > first.message.device_time_us, "the same id without RESEND was not executed anew")
    if "gain" in ctx.params:
        gain = BY_NAME["gain"]
        g1, g2 = gain.lo + 1, gain.lo + 2
        rid = s.send(m.SetConfig({gain.pid: g1}))
        s.wait_reply(rid)
        s.call(m.SetConfig({gain.pid: g2}))
        s.send(m.SetConfig({gain.pid: g1}), rid, FLAG_RESEND)
        s.wait_reply(rid)
        now = ctx.config()["gain"]
        expect(now == g2, f"SET_CONFIG gain={g1} resent after gain={g2}: gain is {now} (applied twice)")
    unseen = s.send(m.GetConfig(), None, FLAG_RESEND)
    expect(isinstance(s.wait_reply(unseen).message, m.Config), "RESEND of a never-seen id not executed")
    d = ctx.status().counters["resends_replayed"] - before.counters["resends_replayed"]
    expect(d >= 1 + ("gain" in ctx.params), f"resends_replayed +{d}")
    return f"TIME and SET_CONFIG replayed, not re-executed (resends_replayed +{d})"


@check("link.resend_trigger", "R-7-2")
def resend_trigger(ctx: Context) -> str:
    """A resent TRIGGER: the same TRIGGERED, the trigger counter +1 only, one capture."""
    ctx.require(m.Capability.SOFTWARE_TRIGGER)
    ctx.apply(trigger_mode=int(TriggerMode.SOFTWARE))
    s = ctx.s
    s.captures.clear()
    s.call(m.Start())
    try:
        before = ctx.status()
        rid = s.send(m.Trigger())
        first = s.wait_reply(rid)
        s.send(m.Trigger(), rid, FLAG_RESEND)
        again = s.wait_reply(rid)
        after = ctx.status()
        ctx.wait_captures(2, 0.5)
    finally:
        ctx.stop()
    expect(isinstance(first.message, m.Triggered), f"TRIGGER answered {first.message!r}")
    assert isinstance(first.message, m.Triggered)
    expect(again.packet == first.packet, f"resent TRIGGER executed twice: answered {again.message!r}, first {first.message!r}")
    d = after.counters["triggers"] - before.counters["triggers"]
    expect(d == 1, f"triggers counter +{d} for one TRIGGER and its RESEND")
    caps = s.captures.snapshot()
    ctx.note_captures(caps)
    expect(len(caps) == 1, f"{len(caps)} captures for one TRIGGER and its RESEND")
    return f"one trigger (id {first.message.trigger_id}), one capture, replay identical"

