"""``stereocam factory report [--db URL] [--since DATE] [--csv FILE]``: yield and metric distributions.

Prints, per day (UTC) and station: attempts, passed, yield, and for the metrics rms_stereo,
epipolar_rms_px (held-out) and baseline_m their median, 90th percentile and maximum over the
attempts that have them. --csv writes every attempt to FILE (metrics as JSON; the calibration blob
as its length in bytes).
"""
from __future__ import annotations

import csv
import json
import re
from collections import defaultdict
from datetime import datetime
from pathlib import Path

import click
import numpy as np

from stereocam.tools.factory.db import (
    COLUMNS,
    GATE_FAILED,
    Attempt,
    FactoryDB,
    FactoryDBError,
    default_url,
)
from stereocam.tools.options import CONTEXT, epilog, output_file

METRICS = ("rms_stereo", "epipolar_rms_px", "baseline_m")


def _stats(values: list[float]) -> str:
    if not values:
        return "-"
    a = np.array(values)
    return f"{np.median(a):.4g}/{np.percentile(a, 90):.4g}/{a.max():.4g}"


def report_lines(attempts: list[Attempt]) -> list[str]:
    """The report table, one line per (day, station) and a total."""
    groups: dict[tuple[str, str], list[Attempt]] = defaultdict(list)
    for a in attempts:
        groups[(a.started_at[:10], a.station)].append(a)
    head = f"{'day':<10} {'station':<16} {'tries':>5} {'pass':>5} {'yield':>6}  " + "  ".join(
        f"{m + ' med/p90/max':<28}" for m in METRICS)
    lines = [head]
    for key in sorted(groups) + [("total", "")]:
        rows = attempts if key[0] == "total" else groups[key]
        passed = sum(a.passed for a in rows)
        yield_ = f"{100 * passed / len(rows):.1f}%" if rows else "-"
        stats = "  ".join(f"{_stats([getattr(a, m) for a in rows if getattr(a, m) is not None]):<28}"
                          for m in METRICS)
        lines.append(f"{key[0]:<10} {key[1]:<16} {len(rows):>5} {passed:>5} {yield_:>6}  {stats}")
    reasons, examples = failure_counts(attempts)
    for kind, n in sorted(reasons.items(), key=lambda kv: -kv[1]):
        example = f"  (latest: {examples[kind]})" if examples[kind] != kind else ""
        lines.append(f"failed {n:>4} x  {kind}{example}")
    return lines


_FIRST_NUMBER = re.compile(r"[-+(]?\d")


def failure_kinds(reason: str) -> list[tuple[str, str]]:
    """(kind, text) for each failure in a failed attempt's reason: each of the gate's failures is its own,
    its kind the words before its first number ("stereo RMS 0.812 px > 0.5 px": "gate: stereo RMS");
    any other reason is its own kind, whole."""
    if not reason.startswith(GATE_FAILED):
        return [(reason, reason)]
    out = []
    for part in filter(None, (p.strip() for p in reason[len(GATE_FAILED):].split("; "))):
        number = _FIRST_NUMBER.search(part)
        words = part[:number.start()].rstrip(" (=,:") if number and number.start() else part
        out.append((f"gate: {words}", part))
    return out or [(reason, reason)]


def failure_counts(attempts: list[Attempt]) -> tuple[dict[str, int], dict[str, str]]:
    """How often each kind of failure happened, and the latest full text of each."""
    counts: dict[str, int] = defaultdict(int)
    latest: dict[str, str] = {}
    for a in sorted(attempts, key=lambda a: a.started_at):
        if not a.passed:
            for kind, text in failure_kinds(a.reason):
                counts[kind] += 1
                latest[kind] = text
    return dict(counts), latest


def report_doc(db: str, attempts: list[Attempt]) -> dict:
    """The report as plain data: per (day, station) and in total, attempts, passes, yield and the
    metrics' median / p90 / max; failure reasons with their counts."""
    groups: dict[str, list[Attempt]] = defaultdict(list)
    for a in attempts:
        groups[f"{a.started_at[:10]} {a.station}"].append(a)

    def summary(rows: list[Attempt]) -> dict:
        out: dict = {"attempts": len(rows), "passed": sum(a.passed for a in rows)}
        out["yield"] = out["passed"] / len(rows) if rows else None
        for m in METRICS:
            v = np.array([getattr(a, m) for a in rows if getattr(a, m) is not None], float)
            out[m] = None if not v.size else {"median": float(np.median(v)), "p90": float(np.percentile(v, 90)),
                                              "max": float(v.max())}
        return out

    reasons, _ = failure_counts(attempts)
    return {"db": db, "groups": {k: summary(v) for k, v in sorted(groups.items())}, "total": summary(attempts),
            "failures": dict(reasons)}


_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")  # what a spreadsheet would run as a formula


def csv_cell(value: object) -> object:
    """``value`` safe for a spreadsheet: text that a spreadsheet would take as a formula gets a
    leading apostrophe (OWASP's CSV injection advice); numbers stay numbers."""
    return "'" + value if isinstance(value, str) and value.startswith(_FORMULA_START) else value


def write_csv(attempts: list[Attempt], path: Path) -> None:
    cols = [c for c in COLUMNS if c != "calibration"] + ["calibration_bytes"]
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for a in attempts:
            d = {**vars(a), "metrics": json.dumps(a.metrics, sort_keys=True)}
            w.writerow([csv_cell(d[c]) for c in cols[:-1]] + [len(a.calibration or b"")])


def _since(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    if value is not None:
        try:
            datetime.fromisoformat(value)
        except ValueError:
            raise click.BadParameter(f"{value!r} is not an ISO date or time (e.g. 2026-11-01)") from None
    return value


def db_url(ctx: click.Context, param: click.Parameter, value: str) -> str:
    """The --db callback (calibrate's too): an empty URL is a usage error, never the default database."""
    if not value.strip():
        raise click.BadParameter("must name a database (a SQLite path, sqlite:///PATH or postgresql://...), "
                                 "got an empty value")
    return value


@click.group("factory", epilog=epilog(), context_settings=CONTEXT)
def command() -> None:
    """The factory record: every calibration attempt, in a SQLite file or on PostgreSQL."""


@command.command("report", epilog=epilog())
@click.option("--db", default=default_url(), show_default=True, callback=db_url, help="SQLite path / sqlite:///PATH or postgresql://...")
@click.option("--since", default=None, callback=_since,
              help="Only attempts from this ISO date (UTC), e.g. 2026-11-01.  [default: all]")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False, path_type=str), default=None, callback=output_file,
              help="Also write every attempt to this CSV file.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object: yield and metrics per day and station.")
def report(db: str, since: str | None, csv_path: Path | None, as_json: bool) -> int:
    """Yield and metric distributions per day (UTC) and station: attempts, passed, yield, and for
    rms_stereo, epipolar_rms_px (held-out) and baseline_m their median, 90th percentile and maximum.
    --csv writes every attempt (metrics as JSON; the calibration blob as its length in bytes)."""
    try:
        with FactoryDB(db, create=False) as fdb:
            attempts = fdb.attempts(since)
            unreadable = fdb.unreadable
    except FactoryDBError as exc:
        raise click.BadParameter(str(exc), param_hint="--db") from None
    for why in unreadable:  # rows written by something else: named, left out of the figures
        click.echo(f"stereocam factory: warning: {db}: {why}: left out of the report", err=True)
    if as_json:
        click.echo(json.dumps(report_doc(db, attempts), indent=2))
    else:
        click.echo(f"factory record {db}: {len(attempts)} attempts" + (f" since {since}" if since else ""))
        click.echo("\n".join(report_lines(attempts)))
    if csv_path is not None:
        write_csv(attempts, csv_path)
        click.echo(f"wrote {csv_path}")
    return 0
