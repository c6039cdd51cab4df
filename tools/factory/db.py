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
from typing import TYPE_CHECKING, Any

from stereocam.protocol.errors import StereoCamError

if TYPE_CHECKING:
    import psycopg
    from psycopg.rows import TupleRow

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
GATE_FAILED = "calibration FAILED the gate: "
"""How the reason of an attempt that failed the quality gate begins; its failures follow, "; "-separated."""
SQLITE_BUSY_S = 10.0  # how long a station waits for another's write lock on a shared SQLite file
_MIGRATION_LOCK = 0x5C_FAC7  # PostgreSQL advisory lock the migration holds (any constant of this tool)
_TEXT = ("unit_serial", "started_at", "station", "tool_version", "mode", "board", "reason", "lens_model",
         "output_dir")
_FLOATS = ("rms_left", "rms_right", "rms_stereo", "epipolar_rms_px", "epipolar_all_rms_px", "fx_left", "baseline_m")
_INTS = ("views_used", "views_dropped")
_BOOLS = ("passed", "written", "verified")


def attempt_from_row(d: dict[str, Any]) -> Attempt:
    """The Attempt of one row as stored, each value checked (others may have written the database):
    ValueError naming the first column that does not hold what it should."""
    def bad(col: str, why: str) -> ValueError:
        return ValueError(f"column {col} {why} ({d[col]!r:.60})")

    for col in _TEXT:
        if d[col] is not None and not isinstance(d[col], str):
            raise bad(col, "is not text")
    for col in _FLOATS + _INTS:
        v = d[col]
        if v is not None and (isinstance(v, bool) or not isinstance(v, int if col in _INTS else (int, float))):
            raise bad(col, "is not a number")
        d[col] = None if v is None else float(v) if col in _FLOATS else v
    for col in _BOOLS:
        if d[col] is not None and d[col] not in (0, 1):
            raise bad(col, "is not true or false")
        d[col] = None if d[col] is None else bool(d[col])
    if d["passed"] is None or d["unit_serial"] is None or d["started_at"] is None:
        raise ValueError("a required column is empty")
    if d["calibration"] is not None and not isinstance(d["calibration"], (bytes, memoryview, bytearray)):
        raise bad("calibration", "is not a binary body")
    d["calibration"] = None if d["calibration"] is None else bytes(d["calibration"])
    try:
        metrics = json.loads(d["metrics"] or "{}")
    except (TypeError, ValueError) as exc:
        raise bad("metrics", "is not JSON") from exc
    if not isinstance(metrics, dict):
        raise bad("metrics", "is not a JSON object")
    d["metrics"] = metrics
    return Attempt(**d)


def default_url() -> str:
    """$STEREOCAM_FACTORY_DB (unset or empty: ~/.local/share/stereocam/factory.sqlite)."""
    return os.environ.get("STEREOCAM_FACTORY_DB") or str(Path.home() / ".local" / "share" / "stereocam" / "factory.sqlite")


class FactoryDB:
    """An open factory database (use as a context manager)."""

    def __init__(self, url: str | None = None, create: bool = True) -> None:
        """``create``: a station recording attempts makes the database (file, folder, tables) where
        it is missing; a reader (report, export) does not: a mistyped path is an error, and a file
        that is not a factory database is left as it was."""
        self.url = default_url() if url is None else url
        if not self.url.strip():
            raise FactoryDBError("factory database: an empty URL (give a SQLite path, sqlite:///PATH or postgresql://...)")
        self.unreadable: list[str] = []  # rows the last ``attempts()`` skipped, and why
        self._conn: sqlite3.Connection | psycopg.Connection[TupleRow]
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
                # autocommit: transactions are begun explicitly (the migration takes the write lock first)
                self.dialect, self._conn = "sqlite", sqlite3.connect(path, timeout=SQLITE_BUSY_S,
                                                                     isolation_level=None)
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

    def _has_table(self, name: str) -> bool:
        cur = self._conn.cursor()
        if self.dialect == "postgresql":
            cur.execute("SELECT to_regclass(%s) IS NOT NULL", (name,))
        else:
            cur.execute("SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name = ?", (name,))
        row = cur.fetchone()
        return row is not None and bool(row[0])

    def version(self) -> int:
        """The schema version applied; 0 where there is no schema_version table (any other error,
        a locked file for one, is raised)."""
        if not self._has_table("schema_version"):
            return 0
        cur = self._conn.cursor()
        cur.execute("SELECT version FROM schema_version")
        row = cur.fetchone()
        return int(row[0]) if row else 0

    def _migrate(self) -> None:
        """Apply the missing migrations in one transaction that holds the database's write lock from
        its start: stations creating the same database at once take turns, none loses its record."""
        cur = self._conn.cursor()
        if self.dialect == "postgresql":
            cur.execute("SELECT pg_advisory_xact_lock(%s)", (_MIGRATION_LOCK,))
        else:
            cur.execute("BEGIN IMMEDIATE")
        try:
            current = self.version()
            if current > SCHEMA_VERSION:
                raise FactoryDBError(f"factory database {self.url} has schema {current}, newer than this tool's "
                                     f"{SCHEMA_VERSION}: update the tool")
            if current == 0:
                cur.execute("CREATE TABLE schema_version (version INTEGER NOT NULL)")
                cur.execute("INSERT INTO schema_version (version) VALUES (0)")
            for version in range(current + 1, SCHEMA_VERSION + 1):
                for statement in MIGRATIONS[version]:
                    cur.execute(statement.format(**_TYPES[self.dialect]))
                cur.execute(self._sql("UPDATE schema_version SET version = ?"), (version,))
            self._commit()
        except BaseException:
            self._rollback()
            raise

    def _commit(self) -> None:
        if not isinstance(self._conn, sqlite3.Connection):
            self._conn.commit()
        elif self._conn.in_transaction:
            self._conn.execute("COMMIT")

    def _rollback(self) -> None:
        if not isinstance(self._conn, sqlite3.Connection):
            self._conn.rollback()
        elif self._conn.in_transaction:
            self._conn.execute("ROLLBACK")

    def record(self, attempt: Attempt) -> int:
        """Insert one attempt; returns its id."""
        row = asdict(attempt)
        row["metrics"] = json.dumps(row["metrics"], sort_keys=True)
        names = ", ".join(COLUMNS)
        marks = ", ".join("?" * len(COLUMNS))
        try:
            cur = self._conn.cursor()
            sql = f"INSERT INTO attempts ({names}) VALUES ({marks})"
            if isinstance(cur, sqlite3.Cursor):
                cur.execute(sql, [row[c] for c in COLUMNS])
                new_id = cur.lastrowid
            else:
                cur.execute(self._sql(sql) + " RETURNING id", [row[c] for c in COLUMNS])
                returned = cur.fetchone()
                new_id = None if returned is None else returned[0]
            if new_id is None:
                raise FactoryDBError("the database gave the new row no id")
            self._commit()
        except Exception as exc:
            self._rollback()
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
        try:
            cur.execute(self._sql(sql.replace("SELECT ", "SELECT id, ", 1) + " ORDER BY started_at, id"), args)
            rows = cur.fetchall()
        except Exception as exc:  # a column dropped, a table renamed, a lock held too long
            self._rollback()
            raise FactoryDBError(f"factory database {self.url}: cannot read the attempts: {exc}") from exc
        self.unreadable = []
        out = []
        for row_id, *values in rows:
            try:
                out.append(attempt_from_row(dict(zip(COLUMNS, values))))
            except ValueError as exc:
                self.unreadable.append(f"attempt {row_id}: {exc}")
        return out
