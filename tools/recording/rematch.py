"""``stereocam rematch RECORDINGS... --out DIR``: match recorded images again, on a Dask cluster.

Each recording is split into frame ranges that follow its chunks; every range is one task (re-match
its frames into a part file), and one task per recording joins the parts into DIR/NAME.mcap: the
original images, camera infos and capture metadata beside the new disparity, and the new matching
configuration in the file's configuration (so replaying it resends the new disparity). Tasks are
retried; outputs are written under temporary names and renamed, so a killed worker loses nothing.
Two recordings of one file name (their outputs would be one file) are refused before any work.

By default a local cluster of worker processes (nothing to set up); ``--scheduler tcp://HOST:PORT``
uses a running Dask scheduler (its workers need stereocam installed and must see the same paths).
"""
from __future__ import annotations

import logging
import os
import time
from pathlib import Path

import click

from stereocam.protocol.errors import ConfigError
from stereocam.protocol.params import BY_NAME
from stereocam.recording.reader import Recording
from stereocam.stereo import engines
from stereocam.stereo.engines import matching_names
from stereocam.presets import POST_PRESETS, preset_values
from stereocam.tools.options import CONTEXT, INPUT_FILE, SETTING, epilog
from stereocam.tools.recording import rematch_tasks as tasks

RETRIES = 3


def check_scheduler(address: str) -> str:
    """``address`` if it reads as a Dask scheduler address (tcp://HOST:PORT and the like), else ConfigError."""
    from distributed.comm import registry
    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        scheme, where = parse_address(address)
        if scheme not in registry.backends:
            raise ValueError(f"unknown protocol {scheme!r} (known: {', '.join(sorted(registry.backends))})")
        if scheme in ("tcp", "tls", "ws", "wss"):
            host, port = parse_host_port(where)
            if not host or not 0 < port < 65536:
                raise ValueError("needs a host and a port from 1 to 65535")
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"scheduler {address!r} is not an address like tcp://HOST:PORT: {exc}") from exc
    return address


def check_matching(names: list[str]) -> None:
    """ConfigError naming those of ``names`` that re-matching cannot change, and the ones it can."""
    allowed = matching_names()
    fixed = [n for n in dict.fromkeys(names) if n not in allowed]
    if fixed:
        raise ConfigError(f"{', '.join(fixed)}: not {'a matching parameter' if len(fixed) == 1 else 'matching parameters'}"
                          f" (rematch re-runs matching on the recorded frames); it takes {', '.join(allowed)}")


def check_workers(workers: object) -> int:
    """``workers`` if it is a number of worker processes (an integer >= 1), else ConfigError."""
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ConfigError(f"workers (local worker processes) must be at least 1, got {workers!r}")
    return workers


def check_names(recordings: list[Path], out: Path) -> None:
    """ConfigError if two recordings would be written to the same ``out``/NAME (outputs keep their
    inputs' names), before any work: one output would replace the other, its parts clash."""
    first: dict[str, Path] = {}
    for p in recordings:
        other = first.setdefault(p.name, p)
        if other is p:
            continue
        if other.resolve() == p.resolve():
            raise ConfigError(f"{p} is given twice: each recording is re-matched once")
        raise ConfigError(f"{other} and {p} would both be written to {out / p.name} (outputs keep their "
                          f"inputs' names): re-match them into separate --out folders")


def check_outputs(recordings: list[Path], out: Path, force: bool) -> None:
    """ConfigError if an output (``out``/NAME of each recording) exists and ``force`` is not given."""
    existing = [str(out / p.name) for p in recordings if os.path.lexists(out / p.name)]
    if existing and not force:
        raise ConfigError(f"{', '.join(existing)} already exist{'s' if len(existing) == 1 else ''}: rematch never "
                          f"replaces a file unless --force")


def _client(scheduler: str | None, workers: int):
    from dask.distributed import Client, LocalCluster

    if scheduler:
        return Client(scheduler, timeout="10s"), None
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=logging.WARNING,  # the cluster's own INFO lines are not ours to print
                           env={"NUMBA_NUM_THREADS": "1"})  # one core per worker: scale by processes
    return Client(cluster), cluster


def rematch(recordings: list[Path], out: Path, overrides: dict[str, int], *, algorithm: str | None = None,
            scheduler: str | None = None, workers: int = 2, chunks_per_task: int = 1, client=None,
            force: bool = False) -> dict:
    """Re-match ``recordings`` into ``out`` with ``algorithm`` ("bm" or "sgm"; None: the recorded
    one) and the recorded settings changed by ``overrides``; returns frames, seconds and the outputs.
    An existing output is a ConfigError unless ``force`` (then it is replaced whole)."""
    check_workers(workers)
    check_names(recordings, out)
    check_outputs(recordings, out, force)
    if scheduler is not None:
        check_scheduler(scheduler)
    if algorithm is not None:
        overrides = {**overrides, "algorithm": engines.engine_named(algorithm).algorithm}
    unknown = set(overrides) - set(BY_NAME)
    if unknown:
        raise ConfigError(f"unknown parameter(s) {sorted(unknown)}")
    check_matching(list(overrides))
    why = [w for k, v in overrides.items() if (w := BY_NAME[k].check(v))]
    if why:
        raise ConfigError("; ".join(why))
    used = {}  # recording -> the algorithm its frames are matched with
    for path in recordings:
        with Recording(path) as rec:  # a bad file or a bad combination fails here, before any work
            cfg = tasks.matching_config(rec.config, overrides)
            try:
                used[path] = engines.selected(cfg).name
                engines.params_from_config(cfg)
            except ValueError as exc:
                raise ConfigError(f"{path}: {exc}") from exc
    out.mkdir(parents=True, exist_ok=True)
    own, cluster = (None, None) if client is not None else _client(scheduler, workers)
    client = client or own
    t0 = time.perf_counter()
    try:
        joins = []
        for path in recordings:
            src = str(path.resolve())
            parts, futures = [], []
            for a, b in tasks.plan(src, chunks_per_task):
                part = str((out / f".{path.name}.{a:08d}-{b:08d}.part.mcap").resolve())  # unique as outputs are
                parts.append(part)
                futures.append(client.submit(tasks.rematch_range, src, a, b, overrides, part, retries=RETRIES,
                                             key=f"rematch-{path.stem}-{a}-{b}-{time.time_ns()}"))
            provenance = {**{k: str(v) for k, v in overrides.items()}, "algorithm": used[path]}
            joins.append(client.submit(_join_after, futures, src, parts, str((out / path.name).resolve()), provenance,
                                       force, retries=RETRIES, key=f"join-{path.stem}-{time.time_ns()}"))
        frames = sum(client.gather(joins))
    finally:
        if own is not None:
            own.close()
        if cluster is not None:
            cluster.close()
    dt = time.perf_counter() - t0
    return {"frames": frames, "seconds": dt, "fps": frames / dt, "outputs": [out / p.name for p in recordings]}


def _join_after(done: list[tuple[int, float]], source: str, parts: list[str], out: str, provenance: dict,
                replace: bool) -> int:
    """Join once every range of the recording is re-matched (``done``: their results)."""
    return tasks.join(source, parts, out, provenance, replace)


def _settings(ctx: click.Context, param: click.Parameter,
              value: tuple[tuple[str, int], ...]) -> tuple[tuple[str, int], ...]:
    try:
        check_matching([name for name, _ in value])
    except ConfigError as exc:
        raise click.BadParameter(str(exc)) from None
    return value


def _scheduler(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    try:
        return None if value is None else check_scheduler(value)
    except ConfigError as exc:
        raise click.BadParameter(str(exc)) from None


@click.command("rematch", epilog=epilog(), context_settings=CONTEXT)
@click.argument("recordings", nargs=-1, required=True, type=INPUT_FILE)
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), required=True,
              help="Folder for the re-matched recordings (not the inputs' folder: outputs keep their names).")
@click.option("--algorithm", type=click.Choice(engines.names()), default=None,
              help="Matcher: bm (block matching) or sgm (semi-global).  [default: the recorded one]")
@click.option("--set", "settings", type=SETTING, multiple=True, callback=_settings,
              help="Matching parameter to change from the recorded configuration (repeatable).")
@click.option("--preset", type=click.Choice(list(POST_PRESETS)), default=None,
              help="A named matching and post-processing preset; --set and --algorithm change it further.")
@click.option("--scheduler", default=None, metavar="tcp://HOST:PORT", callback=_scheduler,
              help="A running Dask scheduler.  [default: a local cluster]")
@click.option("--workers", type=click.IntRange(min=1), default=2, show_default=True,
              help="Local worker processes (without --scheduler).")
@click.option("--chunks-per-task", type=click.IntRange(min=1), default=1, show_default=True,
              help="File chunks per task.")
@click.option("--force", is_flag=True, help="Replace outputs that exist already.")
def command(recordings: tuple[Path, ...], out: Path, algorithm: str | None, settings: tuple[tuple[str, int], ...],
            preset: str | None, scheduler: str | None, workers: int, chunks_per_task: int, force: bool) -> int:
    """Match recorded images again, on a Dask cluster: each recording is split into tasks by chunk,
    re-matched, and joined into OUT/NAME.mcap with the original images and the new disparity."""
    if any(p.resolve().parent == out.resolve() for p in recordings):
        raise click.BadParameter("must not be the folder of the input recordings (outputs keep their names)",
                                 param_hint="--out")
    try:  # before any file is read or cluster started
        check_names(list(recordings), out)
    except ConfigError as exc:
        raise click.BadParameter(str(exc), param_hint="RECORDINGS") from exc
    try:
        check_outputs(list(recordings), out, force)
    except ConfigError as exc:
        raise click.BadParameter(str(exc), param_hint="--out") from None
    overrides = {**(preset_values(preset) if preset else {}), **dict(settings)}
    r = rematch(list(recordings), out, overrides, algorithm=algorithm, scheduler=scheduler,
                workers=workers, chunks_per_task=chunks_per_task, force=force)
    click.echo(f"{r['frames']} frames re-matched in {r['seconds']:.1f} s ({r['fps']:.1f} frames/s) -> "
               + ", ".join(str(p) for p in r["outputs"]))
    return 0
