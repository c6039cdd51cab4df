"""``stereocam record URL --out run.mcap [--frames N | --seconds S]``: record a camera to MCAP.

The file is in the ROS 2 profile (ros2 bag / Foxglove open it): left and right images, disparity,
camera infos from the unit's stored calibration, per-capture metadata; see stereocam.recording.
Extra ``--set name=value`` options configure the camera first (``--set width=1280``).
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

import click
from tqdm import tqdm

import stereocam
from stereocam.protocol.errors import ConfigError
from stereocam.presets import POST_PRESETS
from stereocam.recording.mcapwriter import check_level
from stereocam.tools.camera.session import writable_dir
from stereocam.tools.options import CONTEXT, SETTING, Finite, epilog
from stereocam.tools.progress import progress_wanted


@click.command("record", epilog=epilog(), context_settings=CONTEXT)
@click.argument("url")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="The .mcap file to write (never replaced: it must not exist).")
@click.option("--frames", type=click.IntRange(min=1), default=None, help="Stop after N captures.")
@click.option("--seconds", type=Finite(min=0, min_open=True), default=None, help="Stop after S seconds.")
@click.option("--set", "settings", type=SETTING, multiple=True,
              help="Configure the camera before recording (repeatable), e.g. --set width=1280; "
                   "a value by the name info prints, e.g. --set trigger_mode=software.")
@click.option("--preset", type=click.Choice(list(POST_PRESETS)), default=None,
              help="A named matching and post-processing preset, applied before any --set.")
@click.option("--level", type=int, default=1, show_default=True, help="zstd level of the chunks.")
@click.option("--quiet", is_flag=True, help="No progress bar (there is none when stderr is not a terminal).")
def command(url: str, out: Path, frames: int | None, seconds: float | None, settings: tuple[tuple[str, int], ...],
            preset: str | None, level: int, quiet: bool) -> int:
    """Record a camera to an MCAP file in the ROS 2 profile (ros2 bag / Foxglove open it): left and
    right images, disparity, camera infos from the unit's stored calibration, per-capture metadata.
    Give exactly one of --frames and --seconds."""
    if (frames is None) == (seconds is None):
        raise click.UsageError("give exactly one of --frames N and --seconds S")
    try:  # before the camera is opened: nothing starts on arguments that cannot work
        check_level(level)
    except ConfigError as exc:
        raise click.BadParameter(str(exc), param_hint="--level") from None
    if os.path.lexists(out):
        raise click.BadParameter(f"{out} already exists: a recording never replaces a file; remove it or give "
                                 f"another path", param_hint="--out")
    if not out.parent.is_dir():
        raise click.BadParameter(f"{out.parent} is not a folder", param_hint="--out")
    try:  # a file written into the folder now: permission bits say nothing to root, /proc takes no file
        writable_dir(out.parent)
    except OSError as exc:
        raise click.BadParameter(exc.strerror or str(exc), param_hint="--out") from exc

    bar = tqdm(total=frames or seconds, unit=" frames" if frames else " s", file=sys.stderr,
               disable=quiet or not progress_wanted(), bar_format="{l_bar}{bar}| {n:.%df}/{total:.%df}{unit} [{elapsed}<{remaining}{postfix}]"
               % ((0, 0) if frames else (1, 1)))

    def show(p) -> None:
        c = p.counters
        bar.n = p.frames if frames else min(p.seconds, seconds)
        bar.set_postfix_str(f"{p.fps:.1f} fps, {p.camera_mbps:.1f} MB/s in, {p.file_mbps:.1f} MB/s to disk, drops: "
                            f"gaps {c.link_lost} incomplete {c.link_incomplete} host {c.host_queue_overflow} "
                            f"recorder {c.recorder_dropped}")

    with bar, stereocam.open(url, timeout=2.0) as cam:
        if preset:
            cam.load_preset(preset)
        if settings:
            cam.configure(**dict(settings))
        stats = cam.record(str(out), frames=frames, seconds=seconds, level=level,
                           progress=None if bar.disable else show)
    c = stats.counters
    click.echo(f"{out}: {stats.frames} frames, {stats.file_bytes / 1e6:.1f} MB; drops: sequence gaps {c.link_lost} "
               f"(device skipped {c.device_dropped}), incomplete {c.link_incomplete}, host {c.host_queue_overflow}, "
               f"recorder {stats.recorder_dropped}")
    return 0
