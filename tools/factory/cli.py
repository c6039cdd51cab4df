"""``stereocam factory report [--db URL] [--since DATE] [--csv FILE]``: yield and metric distributions.

Prints, per day (UTC) and station: attempts, passed, yield, and for the metrics rms_stereo,
epipolar_rms_px (held-out) and baseline_m their median, 90th percentile and maximum over the
attempts that have them. --csv writes every attempt to FILE (metrics as JSON; the calibration blob
as its length in bytes).
"""
from __future__ import annotations

from stereocam.tools.exit_codes import EXIT_CODES

import argparse
import csv
import json
import sys
from collections import defaultdict
from datetime import datetime
from pathlib import Path

import numpy as np

from stereocam.tools.factory.db import COLUMNS, Attempt, FactoryDB, FactoryDBError, default_url

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
    reasons: dict[str, int] = defaultdict(int)
    for a in attempts:
        if not a.passed:
            reasons[a.reason.split(":")[0]] += 1
    for reason, n in sorted(reasons.items(), key=lambda kv: -kv[1]):
        lines.append(f"failed {n:>4} x  {reason}")
    return lines


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

    reasons: dict[str, int] = defaultdict(int)
    for a in attempts:
        if not a.passed:
            reasons[a.reason.split(":")[0]] += 1
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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="stereocam factory", description=__doc__.splitlines()[0].replace("``", ""),
                                 epilog=EXIT_CODES,
                                 formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    rep = sub.add_parser("report", help="yield and metric distributions per day and station", epilog=EXIT_CODES,
                         description=__doc__.split("\n\n", 1)[1].strip(),
                         formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    rep.add_argument("--db", default=default_url(), help="SQLite path / sqlite:///PATH or postgresql://...")
    rep.add_argument("--since", default=None, help="only attempts from this ISO date (UTC), e.g. 2026-11-01")
    rep.add_argument("--csv", type=Path, default=None, help="also write every attempt to this CSV file")
    rep.add_argument("--json", action="store_true", help="print one JSON object: yield and metrics per day and station")
    args = ap.parse_args(argv)
    if args.since is not None:
        try:
            datetime.fromisoformat(args.since)
        except ValueError:
            print(f"stereocam factory: error: --since {args.since!r} is not an ISO date or time (e.g. 2026-11-01)",
                  file=sys.stderr)
            return 2
    try:
        with FactoryDB(args.db, create=False) as db:
            attempts = db.attempts(args.since)
            unreadable = db.unreadable
    except FactoryDBError as exc:
        print(f"stereocam factory: error: {exc}", file=sys.stderr)
        return 2
    for why in unreadable:  # rows written by something else: named, left out of the figures
        print(f"stereocam factory: warning: {args.db}: {why}: left out of the report", file=sys.stderr)
    if args.json:
        print(json.dumps(report_doc(args.db, attempts), indent=2))
    else:
        print(f"factory record {args.db}: {len(attempts)} attempts" + (f" since {args.since}" if args.since else ""))
        print("\n".join(report_lines(attempts)))
    if args.csv is not None:
        write_csv(attempts, args.csv)
        print(f"wrote {args.csv}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
