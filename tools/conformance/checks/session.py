"""Whole-run checks, judged last: every message the device sent obeyed the framing rules, and
sequence numbers and device timestamps rose across every stream of the run."""
from __future__ import annotations

from ..context import Context
from ..registry import check
from ..results import expect


@check("session.framing", "R-7-3")
def framing(ctx: Context) -> str:
    """Replies echo the request id with flags 0 and the matching type (or NACK naming the request);
    events carry request id 0; every payload decodes (SPEC §4.0, §7)."""
    v = ctx.s.violations
    expect(not v, f"{len(v)} breaches, first: {'; '.join(v[:3])}")
    st = ctx.s.decoder.stats
    again = f"; link reopened {ctx.reconnects} times after the device dropped it" if ctx.reconnects else ""
    return f"{st.packets} device messages, all well formed; host decoder dropped {st.dropped}{again}"


@check("session.sequences", "R-8.1-1")
def sequences(ctx: Context) -> str:
    """Across every stream of the run: sequence numbers and device timestamps never went back."""
    expect(not ctx.sequence_log, "; ".join(ctx.sequence_log[:3]))
    return f"last sequence {ctx.last_sequence}"
