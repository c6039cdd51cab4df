"""``stereocam bench rematch``: frames/s of ``stereocam rematch`` with 1 and 2 local Dask workers.

A simulator recording (640x480, all planes) is re-matched with another block size, then with the
SGM engine, on a local cluster of 1, then 2 worker processes (one core each); the clusters are
started and their matching kernels loaded before the clock starts, so the figure is the
re-matching itself.
"""
from __future__ import annotations

import logging
import tempfile
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import click

import stereocam
from stereocam.tools.options import CONTEXT, epilog
from stereocam.tools.recording.rematch import _client, rematch


def _warm(_: int = 0) -> None:
    from stereocam.stereo.engines import warm_up

    warm_up()


RUNS: tuple[tuple[str, dict[str, int], str], ...] = (("bm", {"block_size": 21}, "block matching, block_size 15 -> 21"), ("sgm", {}, "SGM, 5 paths (the default)"))


@click.command("rematch", context_settings=CONTEXT, epilog=epilog())
@click.option("--frames", type=click.IntRange(min=1), default=40, show_default=True, help="Frames to record and re-match.")
@click.option("--workers", type=click.IntRange(min=1), multiple=True, default=(1, 2), show_default=True,
              help="Local worker counts to time (repeatable).")
def command(**params: Any) -> int:
    """Frames/s of stereocam rematch with 1 and 2 local Dask workers."""
    args = SimpleNamespace(**params)
    with tempfile.TemporaryDirectory(prefix="stereocam-rematch-") as tmp:
        src = Path(tmp) / "in" / "run.mcap"
        src.parent.mkdir()
        with stereocam.open("sim://?seed=3", timeout=3.0) as cam:
            cam.configure(width=640, height=480, fps=30)
            stats = cam.record(src, frames=args.frames)
        logging.getLogger("distributed").setLevel(logging.WARNING)  # the scheduler runs in this process
        print(f"re-matching {stats.frames} frames of 640x480, chunk-sized tasks:")
        for algorithm, overrides, what in RUNS:
            for n in args.workers:
                client, cluster = _client(None, n)
                try:
                    client.run(_warm)
                    r = rematch([src], Path(tmp) / f"{algorithm}{n}", overrides, algorithm=algorithm, client=client)
                finally:
                    client.close()
                    cluster.close()
                print(f"  {what:<38} {n} worker{'s' if n > 1 else ' '}: {r['fps']:6.1f} frames/s "
                      f"({r['frames']} frames in {r['seconds']:.1f} s)")
    return 0
