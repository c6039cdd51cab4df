"""Trigger modes: software triggers (ids, sequences, frames, refusals, a full queue), external
trigger and the trigger output (the unit as master) where advertised."""
from __future__ import annotations

import time

from stereocam.protocol import messages as m
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.params import BY_NAME, TriggerMode

from ..budget import budget
from ..context import Context
from ..registry import check
from ..results import expect
from ..wire import describe_nack

FRAME_WAIT_S = 3.0
BURST = 6


def _software(ctx: Context) -> None:
    ctx.require(m.Capability.SOFTWARE_TRIGGER)
    ctx.require_params("trigger_mode")
    ctx.apply(trigger_mode=int(TriggerMode.SOFTWARE))


@check("trigger.software", "R-4.6-1", "R-8.5-1")
def software(ctx: Context) -> str:
    """Each TRIGGER: the next trigger id (+1), a new sequence, and one capture carrying both."""
    _software(ctx)
    before = ctx.status()
    ctx.s.captures.clear()
    ctx.s.call(m.Start())
    got = []
    try:
        for _ in range(3):
            r = ctx.s.call(m.Trigger())
            assert isinstance(r, m.Triggered)
            got.append(r)
            deadline = time.monotonic() + budget(FRAME_WAIT_S)
            while (c := ctx.s.captures.find(r.sequence)) is None or c.end is None:
                expect(time.monotonic() < deadline, f"no whole capture of sequence {r.sequence} (trigger {r.trigger_id}) "
                                                    f"within {budget(FRAME_WAIT_S):.3g} s")
                time.sleep(0.01)
            expect(c.begin.trigger_id == r.trigger_id,
                   f"capture {r.sequence} carries trigger id {c.begin.trigger_id}, TRIGGERED said {r.trigger_id}")
    finally:
        ctx.stop()
    after = ctx.status()
    ids, seqs = [r.trigger_id for r in got], [r.sequence for r in got]
    expect(ids == list(range(ids[0], ids[0] + 3)) and ids[0] > 0, f"trigger ids {ids}, expected consecutive from >= 1")
    expect(seqs == sorted(set(seqs)), f"sequences {seqs} not rising")
    caps = ctx.s.captures.snapshot()
    expect(len(caps) == 3, f"{len(caps)} captures for 3 triggers")
    problems = ctx.note_captures(caps)
    expect(not problems, "; ".join(problems))
    d = after.counters["triggers"] - before.counters["triggers"]
    expect(d == 3, f"STATUS triggers counter +{d} for 3 accepted triggers")
    return f"trigger ids {ids}, sequences {seqs}, one capture each"


@check("trigger.refusals", "R-4.4-1")
def refusals(ctx: Context) -> str:
    """TRIGGER while stopped, or while streaming in free-run: NACK BAD_STATE naming trigger_mode."""
    _software(ctx)
    before = ctx.status()
    pid = BY_NAME["trigger_mode"].pid
    r = ctx.s.exchange(m.Trigger())
    expect(isinstance(r, m.Nack) and r.code == ErrorCode.BAD_STATE and r.param_id == pid,
           f"TRIGGER while stopped: {describe_nack(r) if isinstance(r, m.Nack) else r!r}, expected BAD_STATE naming "
           f"trigger_mode ({pid})")
    ctx.apply(trigger_mode=int(TriggerMode.FREE_RUN), fps=BY_NAME["fps"].lo)
    ctx.s.call(m.Start())
    try:
        r = ctx.s.exchange(m.Trigger())
    finally:
        ctx.stop()
    expect(isinstance(r, m.Nack) and r.code == ErrorCode.BAD_STATE and r.param_id == pid,
           f"TRIGGER in free-run: {describe_nack(r) if isinstance(r, m.Nack) else r!r}, expected BAD_STATE naming "
           f"trigger_mode ({pid})")
    d = ctx.status().counters["triggers"] - before.counters["triggers"]
    expect(d == 0, f"refused triggers counted: triggers +{d}")
    return "stopped and free-run TRIGGERs NACKed BAD_STATE naming trigger_mode, not counted"


@check("trigger.burst", "R-4.4-2", "R-4.4-3")
def burst(ctx: Context) -> str:
    """TRIGGERs sent back to back: each TRIGGERED or NACK BUSY; a refused one consumes no sequence
    number, so accepted ones have consecutive sequences; one capture per accepted trigger."""
    _software(ctx)
    ctx.s.captures.clear()
    ctx.s.call(m.Start())
    try:
        rids = [ctx.s.send(m.Trigger()) for _ in range(BURST)]
        replies = [ctx.s.wait_reply(rid).message for rid in rids]
        accepted = [r for r in replies if isinstance(r, m.Triggered)]
        busy = [r for r in replies if isinstance(r, m.Nack)]
        for n in busy:
            expect(n.code == ErrorCode.BUSY and n.param_id == 0, f"burst TRIGGER: {describe_nack(n)}, expected BUSY")
        expect(accepted, "every TRIGGER of the burst refused")
        ctx.wait_captures(len(accepted), FRAME_WAIT_S)
    finally:
        ctx.stop()
    seqs = [r.sequence for r in accepted]
    expect(seqs == list(range(seqs[0], seqs[0] + len(seqs))),
           f"accepted triggers got sequences {seqs}: a BUSY refusal consumed a number, or they are out of order")
    tids = [r.trigger_id for r in accepted]
    expect(tids == list(range(tids[0], tids[0] + len(tids))), f"accepted triggers got ids {tids}")
    caps = ctx.s.captures.snapshot()
    ctx.note_captures(caps)
    got = {(c.sequence, c.begin.trigger_id) for c in caps if c.end is not None}
    expect(got == set(zip(seqs, tids)), f"captures {sorted(got)} for accepted triggers {list(zip(seqs, tids))}")
    paced = _paced_triggers(ctx)
    return (f"{len(accepted)} accepted, {len(busy)} BUSY; sequences {seqs[0]}..{seqs[-1]} consecutive; "
            f"{paced} TRIGGERs each sent after the last one's FRAME_BEGIN all accepted")


def _paced_triggers(ctx: Context, count: int = 3) -> int:
    """SPEC §4.4: a capture stops being pending when its exposure is taken, so a host that waits for
    each FRAME_BEGIN before the next TRIGGER is never refused BUSY (whatever the queue depth)."""
    ctx.s.captures.clear()
    ctx.s.call(m.Start())
    try:
        for k in range(count):
            r = ctx.s.exchange(m.Trigger())
            expect(isinstance(r, m.Triggered), f"TRIGGER {k + 1} sent after the previous capture's FRAME_BEGIN: "
                                               f"{describe_nack(r) if isinstance(r, m.Nack) else r!r}")
            assert isinstance(r, m.Triggered)
            deadline = time.monotonic() + budget(FRAME_WAIT_S)
            while ctx.s.captures.find(r.sequence) is None:
                expect(time.monotonic() < deadline, f"no FRAME_BEGIN for sequence {r.sequence} within "
                                                    f"{budget(FRAME_WAIT_S):.3g} s")
                time.sleep(0.005)
    finally:
        ctx.stop()
    return count


@check("stream.stop_not_dropped", "R-4.6-2")
def stop_not_dropped(ctx: Context) -> str:
    """SPEC §4.6: captures a STOP discards (pending triggers, a free-run stream stopped at once) are
    not counted frames_dropped; the stream they were part of dropped nothing."""
    _software(ctx)
    before = ctx.status()
    ctx.s.call(m.Start())
    try:
        rids = [ctx.s.send(m.Trigger()) for _ in range(BURST)]
        accepted = sum(isinstance(ctx.s.wait_reply(rid).message, m.Triggered) for rid in rids)
    finally:
        ctx.stop()
    mid = ctx.status()
    sent = mid.counters["frames_sent"] - before.counters["frames_sent"]
    dropped = mid.counters["frames_dropped"] - before.counters["frames_dropped"]
    expect(dropped == 0, f"frames_dropped +{dropped} after {accepted} accepted TRIGGERs and a STOP "
                         f"({sent} frames sent): discarded captures are not drops")
    return f"{accepted} triggers accepted, {sent} sent before the STOP, {accepted - sent} discarded; frames_dropped +0"


@check("trigger.external", "R-8.5-2")
def external(ctx: Context) -> str:
    """External mode where advertised: accepted, STATUS reports it, TRIGGER refused; captures that
    arrive (pulses on the line) carry rising non-zero trigger ids. Pulses cannot be made over the wire."""
    ctx.require(m.Capability.EXTERNAL_TRIGGER)
    ctx.require_params("trigger_mode")
    ctx.apply(trigger_mode=int(TriggerMode.EXTERNAL))
    ctx.s.captures.clear()
    ctx.s.call(m.Start())
    try:
        st = ctx.status()
        expect(st.streaming and st.trigger_mode == TriggerMode.EXTERNAL,
               f"STATUS streaming {st.streaming} trigger_mode {st.trigger_mode} after START in external mode")
        r = ctx.s.exchange(m.Trigger())
        expect(isinstance(r, m.Nack) and r.code == ErrorCode.BAD_STATE,
               f"TRIGGER in external mode: {describe_nack(r) if isinstance(r, m.Nack) else r!r}, expected BAD_STATE")
        time.sleep(0.3)
    finally:
        ctx.stop()
    caps = ctx.s.captures.snapshot()
    ctx.note_captures(caps)
    tids = [c.begin.trigger_id for c in caps]
    expect(all(t > 0 for t in tids) and tids == sorted(set(tids)), f"external captures with trigger ids {tids}")
    return f"external mode streams; {len(caps)} pulsed captures seen (pulses are not generated by the suite)"


OUTPUT_FPS = 10
OUTPUT_RUN_S = 1.2
OUTPUT_CAPTURES = int(OUTPUT_RUN_S * OUTPUT_FPS / 2)  # half the pulses of the run: a few dropped aside


@check("trigger.output", "R-8.5-2")
def output(ctx: Context) -> str:
    """Where TRIGGER_OUTPUT is advertised: with ``trigger_output`` = 1 in external mode the unit is
    its own (and its line's) master: while streaming, captures on consecutive trigger ids, one per
    ``1/fps`` of its own clock (per trigger id)."""
    ctx.require(m.Capability.TRIGGER_OUTPUT)
    ctx.require(m.Capability.EXTERNAL_TRIGGER)
    ctx.require_params("trigger_mode", "trigger_output", "fps")
    ctx.apply(trigger_mode=int(TriggerMode.EXTERNAL), trigger_output=1, fps=OUTPUT_FPS)
    ctx.s.captures.clear()
    before = ctx.status()
    ctx.s.call(m.Start())
    try:
        ctx.wait_captures(OUTPUT_CAPTURES, OUTPUT_RUN_S)
    finally:
        ctx.stop()
    time.sleep(0.3)
    dropped = ctx.status().counters["frames_dropped"] - before.counters["frames_dropped"]
    caps = [c for c in ctx.s.captures.snapshot() if c.end is not None]
    problems = ctx.note_captures(caps)
    expect(not problems, "; ".join(problems))
    expect(len(caps) >= OUTPUT_CAPTURES,
           f"{len(caps)} captures in {budget(OUTPUT_RUN_S):.3g} s as trigger master at {OUTPUT_FPS} fps")
    tids = [c.begin.trigger_id for c in caps]
    skipped = tids[-1] - tids[0] + 1 - len(tids)  # pulses between the first and last capture not sent
    expect(all(t > 0 for t in tids) and tids == sorted(set(tids)) and skipped <= dropped,
           f"the master's own pulses gave trigger ids {tids}, expected rising by one except for pulses "
           f"counted in frames_dropped (+{dropped}, §8.4)")
    gaps = sorted((b.begin.device_time_us - a.begin.device_time_us) // (b.begin.trigger_id - a.begin.trigger_id)
                  for a, b in zip(caps, caps[1:]))
    period = gaps[len(gaps) // 2]
    expect(abs(period * OUTPUT_FPS / 1e6 - 1) < 2 * m.CLOCK_DRIFT_MAX,
           f"captures {period} µs apart (median) on the device clock, expected {1e6 / OUTPUT_FPS:.0f} at fps={OUTPUT_FPS}")
    return (f"{len(caps)} captures on its own pulses, ids {tids[0]}..{tids[-1]} ({skipped} skipped, "
            f"frames_dropped +{dropped}), {period} µs apart")
