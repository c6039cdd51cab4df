"""Free-run streaming: rate, sequence numbers and timestamps, capture integrity, disparity
self-description, drop accounting that adds up."""
from __future__ import annotations

import numpy as np

from stereocam.calibration_io import id_text
from stereocam.protocol import messages as m
from stereocam.protocol.params import Output, TriggerMode

from ..captures import Capture
from ..context import Context, StreamRun
from ..registry import check
from ..results import CheckFailed, expect

FREE_RUN_S = 1.5
RATE_TOLERANCE = 0.05  # device-time frame period vs 1/fps


def free_run(ctx: Context) -> StreamRun:
    """One free-run stream at the working configuration, recorded once and judged by several checks."""
    run = ctx.memo.get("free_run")
    if run is None:
        ctx.require_params("trigger_mode", "fps")
        ctx.apply(trigger_mode=int(TriggerMode.FREE_RUN))
        run = ctx.memo["free_run"] = ctx.stream(FREE_RUN_S)
    assert isinstance(run, StreamRun)
    return run


@check("stream.free_run_rate", "R-8.5-3")
def free_run_rate(ctx: Context) -> str:
    """Exposures every 1/fps of device time (within 5 %), trigger id 0."""
    run = free_run(ctx)
    fps = ctx.config()["fps"]
    caps = run.captures
    expect(len(caps) >= 5, f"{len(caps)} captures in {run.seconds:.2f} s of free-run at {fps} fps")
    first, last = caps[0].begin, caps[-1].begin
    expect(last.sequence > first.sequence, "sequence did not advance")
    period = (last.device_time_us - first.device_time_us) / (last.sequence - first.sequence) / 1e6
    expect(abs(period * fps - 1) <= RATE_TOLERANCE,
           f"device-time period {period * 1e3:.2f} ms per sequence number, expected {1e3 / fps:.2f} ms (fps {fps})")
    tids = {c.begin.trigger_id for c in caps}
    expect(tids == {0}, f"free-run captures carry trigger ids {sorted(tids)[:5]}, expected 0")
    return (f"{len(caps)} captures in {run.seconds:.2f} s, period {period * 1e3:.2f} ms for {fps} fps "
            f"({(period * fps - 1) * 100:+.2f} %)")


@check("stream.sequence_and_time", "R-8.4-1", "R-10-1")
def sequence_and_time(ctx: Context) -> str:
    """Sequence numbers and device timestamps rise strictly, across streams too (never reset by START)."""
    run = free_run(ctx)
    expect(not run.sequence_problems, "; ".join(run.sequence_problems[:3]))
    return f"{len(run.captures)} captures, sequences {run.captures[0].sequence}..{run.captures[-1].sequence}" \
        if run.captures else "no captures"


@check("stream.capture_integrity", "R-4.6-3", "R-8.1-1")
def capture_integrity(ctx: Context) -> str:
    """Left, right and disparity of one capture under one sequence between its FRAME_BEGIN and
    FRAME_END, whole planes, byte counts that match; nothing after STOPPED."""
    run = free_run(ctx)
    cfg = ctx.config()
    expect(run.late_messages == 0, f"{run.late_messages} capture messages after STOPPED (SPEC §4.6)")
    problems = capture_problems(run.captures, cfg)
    expect(not problems, "; ".join(problems[:3]))
    expect(not ctx.s.captures.stray, "; ".join(ctx.s.captures.stray[:3]))
    ended = sum(c.end is not None for c in run.captures)
    return f"{ended} whole captures, {len(run.captures) - ended} cut off by STOP, none after STOPPED"


def capture_problems(captures: list[Capture], cfg: dict[str, int]) -> list[str]:
    """What breaks SPEC §4.9 / §8.1 in these captures, against the configuration they were made with."""
    problems = []
    for i, c in enumerate(captures):
        b = c.begin
        where = f"sequence {b.sequence}"
        problems += [f"{where}: {p}" for p in c.problems]
        if c.end is None and i != len(captures) - 1:
            problems.append(f"{where}: no FRAME_END, yet a later capture began")
        if (b.width, b.height) != (cfg["width"], cfg["height"]):
            problems.append(f"{where}: {b.width}x{b.height}, configured {cfg['width']}x{cfg['height']}")
        if "exposure_us" in cfg and (b.exposure_us, b.gain) != (cfg["exposure_us"], cfg["gain"]):
            problems.append(f"{where}: exposure/gain {b.exposure_us}/{b.gain}, configured "
                            f"{cfg['exposure_us']}/{cfg['gain']}")
        raw_planes = ~int(Output.DISPARITY | Output.CONFIDENCE)  # a raw frame has neither
        want = cfg.get("outputs", 7) & (~0 if b.flags & m.FRAME_RECTIFIED else raw_planes)
        if b.planes != want:
            problems.append(f"{where}: planes 0x{b.planes:x}, expected 0x{want:x} (outputs {cfg.get('outputs')}, "
                            f"{'rectified' if b.flags & m.FRAME_RECTIFIED else 'raw'})")
    return problems


@check("stream.disparity_description", "R-4.9-1")
def disparity_description(ctx: Context) -> str:
    """FRAME_BEGIN describes the disparity as configured: format 1, subpixel 16, min/num as set,
    invalid = (min - 1) x 16; rectified frames carry geometry, raw ones none and no disparity;
    every disparity value is the invalid marker or inside the configured range."""
    ctx.require_params("min_disparity", "num_disparities", "trigger_mode")
    cfg = ctx.apply(min_disparity=8, num_disparities=48, trigger_mode=int(TriggerMode.FREE_RUN))
    run = ctx.stream(1.0, frames=3)
    caps = [c for c in run.captures if c.end is not None]
    expect(caps, "no whole capture in 1 s of free-run")
    rectified = 0
    for c in caps:
        b = c.begin
        where = f"sequence {b.sequence}"
        expect(b.disparity_format == m.DISPARITY_S16_Q4 and b.subpixel == 16,
               f"{where}: disparity_format {b.disparity_format} subpixel {b.subpixel}, expected 1 and 16")
        expect((b.min_disparity, b.num_disparities) == (cfg["min_disparity"], cfg["num_disparities"]),
               f"{where}: min/num disparities {b.min_disparity}/{b.num_disparities}, configured "
               f"{cfg['min_disparity']}/{cfg['num_disparities']}")
        expect(b.invalid_disparity == (b.min_disparity - 1) * b.subpixel,
               f"{where}: invalid_disparity {b.invalid_disparity}, expected {(b.min_disparity - 1) * b.subpixel}")
        if b.flags & m.FRAME_RECTIFIED:
            rectified += 1
            expect(b.focal_px > 0 and b.baseline_m > 0 and b.calibration_id,
                   f"{where}: rectified, but focal {b.focal_px} baseline {b.baseline_m} calibration id {id_text(b.calibration_id)}")
            _check_values(c)
        else:
            expect((b.focal_px, b.cx, b.cy, b.baseline_m) == (0, 0, 0, 0) and not b.planes & Output.DISPARITY,
                   f"{where}: raw frame with geometry or a disparity plane")
    return f"{len(caps)} captures ({rectified} rectified) describe min {cfg['min_disparity']} num " \
           f"{cfg['num_disparities']} subpixel 16 as configured"


@check("stream.raw_output", "R-4.9-2")
def raw_output(ctx: Context) -> str:
    """Where RAW_OUTPUT is advertised, rectify=0 gives raw frames: RECTIFIED clear, geometry 0, no
    disparity plane whatever ``outputs`` asks, and the calibration in force still named."""
    ctx.require(m.Capability.RAW_OUTPUT)
    ctx.require_params("rectify", "trigger_mode")
    cfg = ctx.apply(rectify=0, trigger_mode=int(TriggerMode.FREE_RUN))
    info = ctx.s.call(m.GetInfo())
    assert isinstance(info, m.Info)
    run = ctx.stream(1.0, frames=2)
    caps = [c for c in run.captures if c.end is not None]
    expect(caps, "no whole capture in 1 s of free-run with rectify=0")
    problems = capture_problems(run.captures, cfg)
    for c in caps:
        b = c.begin
        if b.flags & m.FRAME_RECTIFIED or (b.focal_px, b.cx, b.cy, b.baseline_m) != (0, 0, 0, 0):
            problems.append(f"sequence {b.sequence}: rectified or with geometry although rectify=0")
        if b.calibration_id != info.calibration_id:
            problems.append(f"sequence {b.sequence}: calibration id {b.calibration_id:08x}, in force "
                            f"{info.calibration_id:08x}")
    expect(not problems, "; ".join(problems[:3]))
    return f"{len(caps)} raw captures, planes 0x{caps[0].begin.planes:x}, no geometry, calibration id named"


def _check_values(c: Capture) -> None:
    raw = c.data.get(int(Output.DISPARITY))
    if raw is None:
        return
    b = c.begin
    d = np.frombuffer(bytes(raw), dtype="<i2")
    valid = d[d != b.invalid_disparity]
    lo, hi = b.min_disparity * b.subpixel, (b.min_disparity + b.num_disparities) * b.subpixel
    outside = valid[(valid < lo) | (valid > hi)]
    if outside.size:
        raise CheckFailed(f"sequence {b.sequence}: {outside.size} disparity values outside {lo}..{hi} "
                          f"(e.g. {int(outside[0])}) that are not the invalid marker {b.invalid_disparity}")


@check("stream.drop_accounting", "R-8.4-1")
def drop_accounting(ctx: Context) -> str:
    """Device counters and what the host received add up (SPEC §4.7, §8.4)."""
    problems, summary = accounting(free_run(ctx), ctx)
    expect(not problems, "; ".join(problems))
    return summary


def accounting(run: StreamRun, ctx: Context) -> tuple[list[str], str]:
    """Whole captures received = frames_sent; FRAME_BEGINs <= frames_captured; sequence gaps are
    exposures the device dropped or captured without sending."""
    ended = sum(c.end is not None for c in run.captures)
    begun = len(run.captures)
    sent, captured, dropped = run.delta("frames_sent"), run.delta("frames_captured"), run.delta("frames_dropped")
    seqs = sorted(c.sequence for c in run.captures)
    gaps = seqs[-1] - seqs[0] + 1 - len(seqs) if seqs else 0
    lossy = ctx.s.decoder.stats.dropped
    problems = []
    if ended != sent and not lossy:
        problems.append(f"the device counts {sent} frames sent, the host received {ended} whole captures")
    if begun > captured:
        problems.append(f"{begun} captures began, the device counts {captured} captured")
    if gaps > dropped + captured - begun:
        problems.append(f"{gaps} sequence numbers missing, but the device counts only {dropped} dropped and "
                        f"{captured - begun} captured without sending")
    summary = (f"host {ended} whole / {begun} begun; device {captured} captured, {sent} sent, {dropped} dropped; "
               f"{gaps} sequence gaps")
    return problems, summary
