"""``stereocam soak URL``: a long fuzz and fault run with counts, outside the CI suite.

1. decoder fuzz: mutated frame streams into fresh decoders (default 1 000 000 inputs);
2. device fuzz: CRC-valid requests with mutated payloads to the device at URL, each must be answered;
3. streaming through a faulty link (byte flips, lost bytes, split writes, latency) at each --flip
   rate for --seconds, counting frames sent / delivered / corrupted / dropped and whether the
   device's and host's counters add up (corruption is checked against the device for sim:// URLs);
4. hostile recordings: compression bombs and fuzzed files through export, repair, replay and
   rematch, counting crashes, hangs, peak memory and files changed outside the output (recordings.py);
5. lying-head group: a CameraGroup of simulated heads, one whose trigger ids jump by 10^6..2^32
   (group.py): crashes, hangs, whether the liar is named, peak memory.
Exit status 1 on any crash, hang, unnamed liar, corrupted frame, counters that do not add up, file
changed outside an output, peak memory over --max-memory-mib (or the group's memory growth over its
limit), or a delivery rate below its goal (VGA frames on a serial-class link: 95 % at 1 byte in 10^5
flipped, 50 % at 1 in 10^4).
"""
from __future__ import annotations

from collections.abc import Callable
from functools import partial

import click

from stereocam.tools.options import CONTEXT, Finite, epilog

from stereocam.device_sim.links.inprocess import SEED_MAX

from .group import HEADS, lying_head_group
from .parts import Report, fuzz_decoder, fuzz_device, stream_with_faults
from .recordings import fuzz_recordings


def _print(rep: Report) -> None:
    click.echo(f"{rep.name}: inputs {rep.inputs}, crashes {rep.crashes}, hangs {rep.hangs}")
    for key, value in rep.figures.items():
        click.echo(f"    {key}: {value}")


MAX_LATENCY = 10.0  # s: the most delay per chunk (a frame's chunks must arrive within the host's deadlines)


DELIVERY_GOALS = {1e-5: 0.95, 1e-4: 0.50}  # byte flip rate -> share of the frames sent that must arrive


def _number(rep: Report, key: str) -> float:
    """A figure its run always counts: a number."""
    value = rep.figures[key]
    if not isinstance(value, (int, float)):
        raise TypeError(f"{rep.name}: figure {key!r} is {value!r}, not a number")
    return value


def _failed(rep: Report, flip: float | None = None) -> bool:
    f = rep.figures
    corrupted = f.get("corrupted", 0)
    goal = DELIVERY_GOALS.get(flip) if flip is not None else None
    short = goal is not None and _number(rep, "delivered") < goal * max(_number(rep, "frames sent"), 1)
    if short:
        f["delivery goal"] = f"NOT MET (at least {goal:.0%})"
    elif goal is not None:
        f["delivery goal"] = f"met (at least {goal:.0%})"
    return bool(rep.crashes or rep.hangs or f.get("invariant violations") or short
                or f.get("files changed outside the output") or str(f.get("memory", "")).startswith("NOT")
                or (isinstance(corrupted, int) and corrupted)
                or str(f.get("liar named", "")).startswith("NO") or f.get("memory goal") == "NOT MET"
                or str(f.get("counters add up", "yes")).startswith("NO"))


def _memory_goal(rep: Report, limit_mib: int) -> Report:
    peak = _number(rep, "peak memory MiB")
    rep.figures["memory"] = f"{'met' if peak <= limit_mib else 'NOT met'} (at most {limit_mib} MiB)"
    return rep


@click.command("soak", context_settings=CONTEXT,
               epilog=epilog("Exit codes: 1 also on any crash, hang, unnamed liar, corrupted frame, counters that "
                             "do not add up, file changed outside an output, memory over its limit, or a delivery "
                             "rate below its goal."))
@click.argument("url", default="sim://?seed=1")
@click.option("--decoder-inputs", type=click.IntRange(min=0), default=1_000_000, show_default=True,
              help="Mutated frame streams fed to fresh decoders.")
@click.option("--device-inputs", type=click.IntRange(min=0), default=5_000, show_default=True,
              help="CRC-valid requests with mutated payloads sent to the device.")
@click.option("--seconds", type=Finite(min=0, min_open=True), default=120.0, show_default=True,
              help="Streaming time per flip rate.")
@click.option("--flip", "flips", type=Finite(0, 1), multiple=True,
              help="Byte flip rate (repeatable).  [default: 1e-5 and 1e-4]")
@click.option("--drop", type=Finite(0, 1), default=1e-6, show_default=True,
              help="Byte loss rate.")
@click.option("--latency", type=Finite(0, MAX_LATENCY), default=0.001, show_default=True,
              help="Most delay per chunk, seconds.")
@click.option("--split", type=click.IntRange(min=1), default=16, show_default=True,
              help="Split host writes into pieces of 1..N bytes.")
@click.option("--chunk", type=click.IntRange(min=0), default=1024, show_default=True,
              help="FRAME_DATA bytes asked for (0: the transport's).")
@click.option("--recording-files", type=click.IntRange(min=0), default=200, show_default=True,
              help="Hostile recordings (3 compression bombs, then fuzzed files; 0: skip the stage).")
@click.option("--max-memory-mib", type=click.IntRange(min=1), default=2048, show_default=True,
              help="Peak memory the hostile-recording stage may reach.")
@click.option("--group-seconds", type=Finite(min=0), default=60.0, show_default=True,
              help="Lying-head group stage (0: skip).")
@click.option("--seed", type=click.IntRange(0, SEED_MAX - (HEADS - 1)), default=0, show_default=True,
              help="Seed of every random choice.")
def command(url: str, decoder_inputs: int, device_inputs: int, seconds: float, flips: tuple[float, ...], drop: float,
            latency: float, split: int, chunk: int, recording_files: int, max_memory_mib: int, group_seconds: float,
            seed: int) -> int:
    """A long fuzz and fault run with counts, outside the CI suite: (1) mutated frame streams into
    fresh decoders; (2) CRC-valid requests with mutated payloads to the device at URL, each must be
    answered; (3) streaming through a faulty link (byte flips, lost bytes, split writes, latency) at
    each --flip rate for --seconds, counting frames sent / delivered / corrupted / dropped and whether
    the device's and host's counters add up. Delivery goals (VGA frames on a serial-class link): 95 %
    at 1 byte in 10^5 flipped, 50 % at 1 in 10^4; (4) compression bombs and fuzzed recordings through
    export, repair, replay and rematch; (5) a camera group with a head lying about its trigger ids."""
    runs: list[tuple[float | None, Callable[[], Report]]] = [
        (None, lambda: fuzz_decoder(decoder_inputs, seed)),
        (None, lambda: fuzz_device(url, device_inputs, seed))]
    runs += [(flip, partial(stream_with_faults, url, seconds, flip, drop, latency, split, chunk or None, seed=seed))
             for flip in flips or (1e-5, 1e-4)]
    if recording_files > 0:
        runs.append((None, lambda: _memory_goal(fuzz_recordings(recording_files, seed), max_memory_mib)))
    if group_seconds > 0:
        runs.append((None, lambda: lying_head_group(group_seconds, seed=seed)))
    bad = []
    for flip, run in runs:  # one at a time, each printed as it ends
        rep = run()
        if _failed(rep, flip):
            bad.append(rep.name)
        _print(rep)
    click.echo("soak: " + (f"FAILED ({', '.join(bad)})" if bad else "clean"))
    return 1 if bad else 0
