"""``stereocam record URL --out run.mcap [--frames N | --seconds S]``: record a camera to MCAP.

The file is in the ROS 2 profile (ros2 bag / Foxglove open it): left and right images, disparity,
camera infos from the unit's stored calibration, per-capture metadata; see stereocam.recording.
Extra ``--set name=value`` options configure the camera first (``--set width=1280``).
"""
from __future__ import annotations

from stereocam.tools.exit_codes import EXIT_CODES, EXIT_USAGE

import argparse
import os
import sys

from tqdm import tqdm

import stereocam
from stereocam.protocol.errors import ConfigError
from stereocam.recording.mcapwriter import check_level


def _setting(text: str) -> tuple[str, int]:
    name, sep, value = text.partition("=")
    try:
        return name, int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--set takes name=integer, got {text!r}") from None


def _usage(text: str) -> int:
    print(f"stereocam record: error: {text}", file=sys.stderr)
    return EXIT_USAGE


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="stereocam record", description=__doc__.splitlines()[0].replace("``", ""),
                                 epilog=EXIT_CODES)
    ap.add_argument("url")
    ap.add_argument("--out", required=True, help="the .mcap file to write")
    limit = ap.add_mutually_exclusive_group(required=True)
    limit.add_argument("--frames", type=int, help="stop after N captures")
    limit.add_argument("--seconds", type=float, help="stop after S seconds")
    ap.add_argument("--set", type=_setting, action="append", default=[], metavar="NAME=VALUE",
                    help="configure the camera before recording (repeatable)")
    ap.add_argument("--level", type=int, default=1, help="zstd level of the chunks (default 1)")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    args = ap.parse_args(argv)
    if (args.frames is not None and args.frames <= 0) or (args.seconds is not None and args.seconds <= 0):
        raise ConfigError("--frames and --seconds must be positive")
    try:  # before the camera is opened: nothing starts on arguments that cannot work
        check_level(args.level)
    except ConfigError as exc:
        return _usage(f"--level: {exc}")
    if os.path.lexists(args.out):
        return _usage(f"--out {args.out} already exists: a recording never replaces a file; remove it or give "
                      f"another path")

    bar = tqdm(total=args.frames or args.seconds, unit=" frames" if args.frames else " s", file=sys.stderr,
               disable=args.quiet, bar_format="{l_bar}{bar}| {n:.%df}/{total:.%df}{unit} [{elapsed}<{remaining}{postfix}]"
               % ((0, 0) if args.frames else (1, 1)))

    def show(p) -> None:
        c = p.counters
        bar.n = p.frames if args.frames else min(p.seconds, args.seconds)
        bar.set_postfix_str(f"{p.fps:.1f} fps, {p.camera_mbps:.1f} MB/s in, {p.file_mbps:.1f} MB/s to disk, drops: "
                            f"gaps {c.link_lost} incomplete {c.link_incomplete} host {c.host_queue_overflow} "
                            f"recorder {c.recorder_dropped}")

    with bar, stereocam.open(args.url, timeout=2.0) as cam:
        if args.set:
            cam.configure(**dict(args.set))
        stats = cam.record(args.out, frames=args.frames, seconds=args.seconds, level=args.level,
                           progress=None if args.quiet else show)
    c = stats.counters
    print(f"{args.out}: {stats.frames} frames, {stats.file_bytes / 1e6:.1f} MB; drops: sequence gaps {c.link_lost} "
          f"(device skipped {c.device_dropped}), incomplete {c.link_incomplete}, host {c.host_queue_overflow}, "
          f"recorder {stats.recorder_dropped}")
    return 0
