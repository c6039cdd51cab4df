"""Post-processing (SPEC §5.3): the capability bit and its parameters go together, and each stage
changes the disparity exactly as the host's chain (stereocam.stereo.post) does to the engine's output
of the same captured pair."""
from __future__ import annotations

from typing import Iterator

import numpy as np

from stereocam.protocol import messages as m
from stereocam.protocol.params import Algorithm, Output, TriggerMode

from ..captures import Capture
from ..context import Context
from ..registry import CheckFn, check, family
from ..results import CheckFailed, expect

POST_PARAMS = ("lr_check", "hole_fill", "spatial_alpha", "spatial_delta", "spatial_iterations", "temporal_alpha",
               "temporal_delta", "temporal_persistence", "median_size", "decimation")
STAGES: dict[str, dict[str, int]] = {
    "lr_check": {"lr_check": 1},
    "hole_fill_nearest": {"hole_fill": 1},
    "hole_fill_background": {"hole_fill": 2},
    "spatial": {"spatial_alpha": 128, "spatial_delta": 32, "spatial_iterations": 2},
    "temporal": {"temporal_alpha": 100, "temporal_delta": 32, "temporal_persistence": 3},
    "median": {"median_size": 3},
    "decimation": {"decimation": 2},
}
"""One setting per stage that must change the output of the working configuration's scene."""
FRAMES = 2  # consecutive captures judged per stage (the temporal filter's state carries across them)
CAPTURE_BUDGET_S = 10.0  # per triggered capture


@check("post.capability", "R-5.3-1")
def capability(ctx: Context) -> str:
    """POST_PROCESSING in INFO exactly when CONFIG lists the post-processing parameters, which
    default to every stage off."""
    listed = [n for n in POST_PARAMS if n in ctx.params]
    has = ctx.has(m.Capability.POST_PROCESSING)
    expect(not has or len(listed) == len(POST_PARAMS),
           f"POST_PROCESSING advertised but CONFIG lacks {sorted(set(POST_PARAMS) - set(listed))}")
    expect(has or not listed, f"CONFIG lists {listed} without POST_PROCESSING in INFO.capabilities")
    if not has:
        return "not advertised; no post-processing parameters"
    from stereocam.stereo.post import post_params_from_config

    defaults = {n: int(ctx.params[n].default) for n in POST_PARAMS}
    expect(not post_params_from_config(defaults).active, f"the table's defaults turn a stage on: {defaults}")
    return f"advertised with its {len(listed)} parameters"


@family("post.stage", "R-5.3-2")
def stages(ctx: Context) -> Iterator[tuple[str, CheckFn]]:
    """One check per stage: its output matches the host's chain on the device's own captures."""
    for name, values in STAGES.items():
        yield name, _stage_check(values)


def _planes(c: Capture) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    b = c.begin
    shape = (b.height, b.width)
    left = np.frombuffer(bytes(c.data[int(Output.LEFT)]), np.uint8).reshape(shape)
    right = np.frombuffer(bytes(c.data[int(Output.RIGHT)]), np.uint8).reshape(shape)
    disp = np.frombuffer(bytes(c.data[int(Output.DISPARITY)]), "<i2").reshape(shape).astype(np.int16)
    return left, right, disp


def _triggered(ctx: Context, count: int) -> list[Capture]:
    """``count`` captures, each triggered once the previous one has ended."""
    ctx.s.captures.clear()
    ctx.s.call(m.Start())
    try:
        for i in range(count):
            ctx.s.call(m.Trigger())
            ctx.wait_captures(i + 1, CAPTURE_BUDGET_S)
    finally:
        ctx.stop()
    caps = [c for c in ctx.s.captures.snapshot() if c.end is not None and not c.problems]
    ctx.note_captures(caps)
    expect(len(caps) == count and all(b.sequence == a.sequence + 1 for a, b in zip(caps, caps[1:])),
           f"{len(caps)} whole captures of {count} triggered ones, consecutive: "
           f"{[c.sequence for c in caps]}")
    return caps


def _stage_check(values: dict[str, int]) -> CheckFn:
    def run(ctx: Context) -> str:
        ctx.require(m.Capability.POST_PROCESSING)
        from stereocam.stereo import match
        from stereocam.stereo.engines import params_from_config
        from stereocam.stereo.post import PostChain, post_params_from_config, postprocess

        ctx.require(m.Capability.SOFTWARE_TRIGGER)
        algorithm = Algorithm.SEMI_GLOBAL if "algorithm" in ctx.params else Algorithm.BLOCK_MATCHING
        # triggered one at a time, well within 3 frame periods (SPEC §5.3: no gap resets the temporal state)
        ctx.apply(trigger_mode=int(TriggerMode.SOFTWARE), fps=1, rectify=1, algorithm=int(algorithm),
                  outputs=int(Output.LEFT | Output.RIGHT | Output.DISPARITY))
        cfg = {**ctx.apply(**values), **values}  # judged against what was asked, whatever the device holds
        caps = _triggered(ctx, FRAMES)
        engine, post = params_from_config(cfg), post_params_from_config(cfg)
        chain = PostChain(post, engine.min_disparity)
        changed = 0
        for c in caps:
            left, right, sent = _planes(c)
            raw = match(left, right, engine)
            want = postprocess(raw, left, post, right, engine, chain)
            differ = np.count_nonzero(sent != want)
            if differ:
                raise CheckFailed(f"{', '.join(f'{k}={v}' for k, v in values.items())}: sequence {c.sequence} "
                                  f"differs from the host's chain at {differ} of {sent.size} pixels "
                                  f"({np.count_nonzero(sent != raw)} differ from the engine's raw output)")
            changed += int(np.count_nonzero(want != raw))
        expect(changed > 0, "the stage changed no pixel of the scene: nothing was judged")
        return (f"{', '.join(f'{k}={v}' for k, v in values.items())}: {FRAMES} captures as the host's chain, "
                f"{changed} pixels changed by it")
    return run
