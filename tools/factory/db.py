"""The factory database: one row per calibration attempt, SQLite or PostgreSQL, versioned schema.

URL: a file path or ``sqlite:///PATH`` → SQLite (created by a station, never by a report);
``postgresql://...`` →
PostgreSQL through psycopg (a line of stations shares one record). The default is
$STEREOCAM_FACTORY_DB, else ~/.local/share/stereocam/factory.sqlite.

Schema versions (table ``schema_version`` holds the one applied; open() applies the missing
migrations in order, inside a transaction, and refuses a database newer than this tool):
  1  table ``attempts``: unit_serial, started_at (ISO-8601 UTC), station, tool_version, mode
     (device | offline), board, lens_model, passed, reason, rms_left, rms_right, rms_stereo,
     epipolar_rms_px, views_used, calibration (the body as written to the device), output_dir
  2  adds epipolar_all_rms_px, views_dropped, fx_left, baseline_m, written, verified and
     metrics (JSON of every metric of the attempt)
"""
from __future__ import annotations

import json
import os
import sqlite3
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from stereocam.protocol.errors import StereoCamError

SCHEMA_VERSION = 2
_TYPES = {"sqlite": {"id": "INTEGER PRIMARY KEY AUTOINCREMENT", "blob": "BLOB", "bool": "INTEGER"},
          "postgresql": {"id": "BIGSERIAL PRIMARY KEY", "blob": "BYTEA", "bool": "BOOLEAN"}}
MIGRATIONS: dict[int, list[str]] = {
    1: ["CREATE TABLE attempts (id {id}, unit_serial TEXT NOT NULL, started_at TEXT NOT NULL, "
        "station TEXT NOT NULL, tool_version TEXT NOT NULL, mode TEXT NOT NULL, board TEXT NOT NULL, "
        "lens_model TEXT, passed {bool} NOT NULL, reason TEXT NOT NULL, rms_left DOUBLE PRECISION, "
        "rms_right DOUBLE PRECISION, rms_stereo DOUBLE PRECISION, epipolar_rms_px DOUBLE PRECISION, "
        "views_used INTEGER, calibration {blob}, output_dir TEXT)",
        "CREATE INDEX attempts_started ON attempts (started_at)"],
    2: [f"ALTER TABLE attempts ADD COLUMN {col}" for col in (
        "epipolar_all_rms_px DOUBLE PRECISION", "views_dropped INTEGER", "fx_left DOUBLE PRECISION",
        "baseline_m DOUBLE PRECISION", "written {bool}", "verified {bool}", "metrics TEXT")],
}


class FactoryDBError(StereoCamError):
    """The factory database cannot be opened, migrated or written."""


@dataclass
class Attempt:
    """One calibration attempt as recorded."""

    unit_serial: str
    started_at: str
    station: str
    tool_version: str
    mode: str
    board: str
    passed: bool
    reason: str
    lens_model: str | None = None
    rms_left: float | None = None
    rms_right: float | None = None
    rms_stereo: float | None = None
    epipolar_rms_px: float | None = None
    epipolar_all_rms_px: float | None = None
    views_used: int | None = None
    views_dropped: int | None = None
    fx_left: float | None = None
    baseline_m: float | None = None
    written: bool | None = None
    verified: bool | None = None
    calibration: bytes | None = None
    output_dir: str | None = None
    metrics: dict[str, Any] = field(default_factory=dict)


COLUMNS = [f for f in Attempt.__dataclass_fields__]


def default_url() -> str:
    return os.environ.get("STEREOCAM_FACTORY_DB",
                          str(Path.home() / ".local" / "share" / "stereocam" / "factory.sqlite"))


class FactoryDB:
    """An open factory database (use as a context manager)."""

    def __init__(self, url: str | None = None, create: bool = True) -> None:
        """``create``: a station recording attempts makes the database (file, folder, tables) where
        it is missing; a reader (report, export) does not: a mistyped path is an error, and a file
        that is not a factory database is left as it was."""
        self.url = url or default_url()
        scheme = self.url.split("://", 1)[0] if "://" in self.url else ""
        if scheme not in ("", "sqlite", "postgresql", "postgres"):
            raise FactoryDBError(f"factory database {self.url}: unknown scheme {scheme!r} "
                                 "(a file path, sqlite:///PATH or postgresql://...)")
        try:
            if scheme.startswith("postgres"):
                import psycopg

                self.dialect, self._conn = "postgresql", psycopg.connect(self.url)
            else:
                path = Path(self.url.removeprefix("sqlite:///").removeprefix("sqlite://"))
                if create:
                    path.parent.mkdir(parents=True, exist_ok=True)
                elif not path.is_file():
                    raise FactoryDBError(f"no factory database at {path} (a report never creates one)")
                self.dialect, self._conn = "sqlite", sqlite3.connect(path)
            if not create and self.version() == 0:
                self._conn.close()
                raise FactoryDBError(f"{self.url} is not a factory database (no schema_version table); left as it was")
            self._migrate()
        except FactoryDBError:
            raise
        except Exception as exc:  # sqlite3.Error, psycopg.Error, OSError: all mean "cannot use it"
            raise FactoryDBError(f"factory database {self.url}: {exc}") from exc

    def __enter__(self) -> "FactoryDB":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._conn.close()

    def _sql(self, text: str) -> str:
        return text.replace("?", "%s") if self.dialect == "postgresql" else text

    def version(self) -> int:
        cur = self._conn.cursor()
        try:
            cur.execute("SELECT version FROM schema_version")
        except Exception:
            self._conn.rollback()
            return 0
        row = cur.fetchone()
        return int(row[0]) if row else 0

    def _migrate(self) -> None:
        current = self.version()
        if current > SCHEMA_VERSION:
            raise FactoryDBError(f"factory database {self.url} has schema {current}, newer than this tool's "
                                 f"{SCHEMA_VERSION}: update the tool")
        cur = self._conn.cursor()
        if current == 0:
            cur.execute("CREATE TABLE schema_version (version INTEGER NOT NULL)")
            cur.execute("INSERT INTO schema_version (version) VALUES (0)")
        for version in range(current + 1, SCHEMA_VERSION + 1):
            for statement in MIGRATIONS[version]:
                cur.execute(statement.format(**_TYPES[self.dialect]))
            cur.execute(self._sql("UPDATE schema_version SET version = ?"), (version,))
        self._conn.commit()

    def record(self, attempt: Attempt) -> int:
        """Insert one attempt; returns its id."""
        row = asdict(attempt)
        row["metrics"] = json.dumps(row["metrics"], sort_keys=True)
        names = ", ".join(COLUMNS)
        marks = ", ".join("?" * len(COLUMNS))
        try:
            cur = self._conn.cursor()
            sql = f"INSERT INTO attempts ({names}) VALUES ({marks})"
            if self.dialect == "postgresql":
                cur.execute(self._sql(sql) + " RETURNING id", [row[c] for c in COLUMNS])
                new_id = cur.fetchone()[0]
            else:
                cur.execute(sql, [row[c] for c in COLUMNS])
                new_id = cur.lastrowid
            self._conn.commit()
        except Exception as exc:
            self._conn.rollback()
            raise FactoryDBError(f"factory database {self.url}: cannot record the attempt: {exc}") from exc
        return int(new_id)

    def attempts(self, since: str | None = None) -> list[Attempt]:
        """Attempts started at or after `since` (ISO date or time), oldest first."""
        sql = f"SELECT {', '.join(COLUMNS)} FROM attempts"
        args: list[Any] = []
        if since:
            sql += " WHERE started_at >= ?"
            args.append(since)
        cur = self._conn.cursor()
        cur.execute(self._sql(sql + " ORDER BY started_at, id"), args)
        out = []
        for values in cur.fetchall():
            d = dict(zip(COLUMNS, values))
            d["metrics"] = json.loads(d["metrics"] or "{}")
            for key in ("passed", "written", "verified"):
                d[key] = None if d[key] is None else bool(d[key])
            d["calibration"] = None if d["calibration"] is None else bytes(d["calibration"])
            out.append(Attempt(**d))
        return out
