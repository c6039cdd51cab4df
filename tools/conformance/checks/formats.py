"""Streaming at each standard format the device advertises (within INFO.max_width/max_height
and the table's steps), with whole captures of that size and drop accounting that adds up."""
from __future__ import annotations

from typing import Iterator

from stereocam.protocol.params import BY_NAME, TriggerMode

from ..context import Context
from ..registry import CheckFn, family
from ..results import expect
from .streaming import accounting, capture_problems

STANDARD = ((64, 48), (160, 120), (320, 240), (640, 480), (1280, 960))
SECONDS = 5.0  # at most, per format (returns once FRAMES whole captures are in)
FRAMES = 2
FPS = 5  # low enough that a device computing full-size disparity keeps up
BLOCK = 9


def formats(max_width: int, max_height: int) -> list[tuple[int, int]]:
    """Standard sizes that fit, plus the largest the device advertises."""
    w, h = BY_NAME["width"], BY_NAME["height"]
    largest = (max_width - (max_width - w.lo) % w.step, max_height - (max_height - h.lo) % h.step)
    fit = [(x, y) for x, y in STANDARD if x <= largest[0] and y <= largest[1]]
    return sorted(set(fit) | {largest})


@family("stream.format", "R-8.2-1")
def each_format(ctx: Context) -> Iterator[tuple[str, CheckFn]]:
    ctx.require_params("width", "height", "trigger_mode", "fps")
    for w, h in formats(ctx.info.max_width, ctx.info.max_height):
        yield f"{w}x{h}", _format_check(w, h)


def _format_check(w: int, h: int) -> CheckFn:
    def run(ctx: Context) -> str:
        span = w - 1 - BLOCK // 2  # min_disparity 0: num_disparities + block/2 < width (SPEC §5.2)
        num = max(BY_NAME["num_disparities"].lo, min(64, span - span % 16))
        cfg = ctx.apply(width=w, height=h, num_disparities=num, block_size=BLOCK, pre_filter_size=BLOCK,
                        min_disparity=0, trigger_mode=int(TriggerMode.FREE_RUN), fps=FPS)
        run = ctx.stream(SECONDS, frames=FRAMES)
        whole = [c for c in run.captures if c.end is not None]
        expect(whole, f"no whole capture in {run.seconds:.1f} s at {w}x{h}, {FPS} fps")
        problems = capture_problems(run.captures, cfg) + run.sequence_problems
        expect(run.late_messages == 0, f"{run.late_messages} capture messages after STOPPED")
        bad, summary = accounting(run, ctx)
        expect(not problems + bad, "; ".join((problems + bad)[:3]))
        return f"{len(whole)} whole captures in {run.seconds:.2f} s; {summary}"
    return run
