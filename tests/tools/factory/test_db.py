"""The factory record against SQLite and a real PostgreSQL server (pgserver's packaged binaries)."""
from __future__ import annotations

import csv
import json
import sqlite3
from pathlib import Path

import pytest

from tests.support.paths import DATA

from stereocam.tools.calibration import calibrate
from stereocam.tools import cli
from stereocam.tools.factory.db import MIGRATIONS, SCHEMA_VERSION, Attempt, FactoryDB, FactoryDBError

PAIRS = DATA / "opencv_chessboard_pairs"


@pytest.fixture(scope="module")
def postgres_url(tmp_path_factory: pytest.TempPathFactory):
    pgserver = pytest.importorskip("pgserver", reason="pgserver (packaged PostgreSQL) is not installed")
    try:
        server = pgserver.get_server(tmp_path_factory.mktemp("pg"), cleanup_mode="stop")
    except Exception as exc:  # no server can be started here (e.g. no shared memory)
        pytest.skip(f"cannot start a PostgreSQL server: {exc}")
    yield server.get_uri()
    server.cleanup()


@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request, tmp_path: Path) -> str:
    if request.param == "sqlite":
        return str(tmp_path / "factory.sqlite")
    url = request.getfixturevalue("postgres_url")
    with FactoryDB(url) as db:  # a clean table per test
        cur = db._conn.cursor()
        cur.execute("DELETE FROM attempts")
        db._conn.commit()
    return url


def _run(db_url: str, out: Path, *extra: str) -> int:
    return cli.main(["calibrate", "-q", "--images", str(PAIRS), "--board", "9x6", "--square-size", "0.025",
                           "--out", str(out), "--db", db_url, "--station", "line-1", *extra])


def test_every_attempt_is_recorded_and_reported(db_url: str, tmp_path: Path, capsys) -> None:
    # one lens model: what is recorded, not the model race (test_calib_real_pairs races on these pairs)
    assert _run(db_url, tmp_path / "a", "--lens-model", "plumb_bob") == 0
    assert _run(db_url, tmp_path / "b", "--max-epipolar", "0.01", "--lens-model", "plumb_bob", "--station", "line-2",
                "--serial", "SN-7") == calibrate.EXIT_GATE
    with FactoryDB(db_url) as db:
        rows = db.attempts()
        assert db.version() == SCHEMA_VERSION
    assert [(r.passed, r.station) for r in rows] == [(True, "line-1"), (False, "line-2")]
    ok, bad = rows
    assert ok.unit_serial == "opencv_chessboard_pairs" and bad.unit_serial == "SN-7"
    assert ok.mode == "offline" and ok.board == "9x6:0.025" and ok.lens_model == "plumb_bob"
    assert ok.rms_stereo > 0 and ok.epipolar_rms_px > 0 and ok.views_used >= 12 and ok.baseline_m > 0.05
    assert ok.metrics["lens_model_scores"] and ok.output_dir == str((tmp_path / "a").resolve())
    assert ok.calibration is None and ok.written is False        # offline: nothing written to a device
    assert "epipolar" in bad.reason and bad.metrics["failures"]
    capsys.readouterr()
    day = ok.started_at[:10]
    assert cli.main(["factory", "report", "--db", db_url, "--since", day, "--csv", str(tmp_path / "r.csv")]) == 0
    out = capsys.readouterr().out
    assert "2 attempts" in out and "line-1" in out and "line-2" in out and "50.0%" in out
    assert "gate: held-out epipolar RMS" in out and "> 0.01 px" in out  # the reason, not its first words
    with (tmp_path / "r.csv").open() as f:
        table = list(csv.DictReader(f))
    assert [t["station"] for t in table] == ["line-1", "line-2"] and float(table[0]["rms_stereo"]) > 0
    assert json.loads(table[0]["metrics"])["lens_model_scores"] == ok.metrics["lens_model_scores"]
    assert cli.main(["factory", "report", "--db", db_url, "--since", "2999-01-01"]) == 0
    assert "0 attempts" in capsys.readouterr().out
    assert cli.main(["factory", "report", "--db", db_url, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert (doc["total"]["attempts"], doc["total"]["passed"], doc["total"]["yield"]) == (2, 1, 0.5)
    assert set(doc["groups"]) == {f"{day} line-1", f"{day} line-2"}
    assert doc["groups"][f"{day} line-1"]["rms_stereo"]["median"] == ok.rms_stereo
    assert doc["failures"] == {"gate: held-out epipolar RMS": 1}


def test_device_blob_round_trips(db_url: str) -> None:
    blob = bytes(range(256)) * 2
    with FactoryDB(db_url) as db:
        db.record(Attempt("SN-1", "2026-01-02T03:04:05Z", "s", "0.2", "device", "9x6:0.03", True, "ok",
                          calibration=blob, written=True, verified=True, metrics={"a": 1.5}))
        (row,) = db.attempts()
    assert row.calibration == blob and row.written is True and row.metrics == {"a": 1.5}


def test_sqlite_migrates_a_version_1_database(tmp_path: Path) -> None:
    path = tmp_path / "old.sqlite"
    con = sqlite3.connect(path)
    con.execute("CREATE TABLE schema_version (version INTEGER NOT NULL)")
    con.execute("INSERT INTO schema_version VALUES (1)")
    for statement in MIGRATIONS[1]:
        con.execute(statement.format(id="INTEGER PRIMARY KEY AUTOINCREMENT", blob="BLOB", bool="INTEGER"))
    con.execute("INSERT INTO attempts (unit_serial, started_at, station, tool_version, mode, board, passed, reason) "
                "VALUES ('SN-0', '2025-12-31T23:00:00Z', 'old', '0.1', 'device', '9x6', 1, 'passed')")
    con.commit()
    con.close()
    with FactoryDB(str(path)) as db:
        assert db.version() == SCHEMA_VERSION
        (row,) = db.attempts()
    assert row.unit_serial == "SN-0" and row.passed is True and row.metrics == {} and row.baseline_m is None


def test_newer_schema_and_unusable_db_are_refused_before_anything(tmp_path: Path, capsys) -> None:
    path = tmp_path / "new.sqlite"
    with FactoryDB(str(path)) as db:
        db._conn.execute("UPDATE schema_version SET version = 99")
        db._conn.commit()
    with pytest.raises(FactoryDBError, match="newer than this tool"):
        FactoryDB(str(path))
    out = tmp_path / "out"
    assert _run(str(path), out) == calibrate.EXIT_USAGE
    assert "nothing was done" in capsys.readouterr().err and not out.exists()
    assert _run("postgresql://nobody@127.0.0.1:1/none", out) == calibrate.EXIT_USAGE
    (tmp_path / "file").write_text("x")
    assert _run(str(tmp_path / "db.sqlite"), tmp_path / "file" / "sub") == calibrate.EXIT_USAGE
    assert "cannot write into directory" in capsys.readouterr().err


def test_a_report_never_creates_or_changes_a_database(tmp_path: Path, capsys) -> None:
    """A mistyped --db is an error, not an empty record; another program's SQLite file is left as
    it was; an unknown scheme or a --since that is not a date is refused."""
    missing = tmp_path / "nodir" / "f.sqlite"
    other = tmp_path / "other.sqlite"
    con = sqlite3.connect(other)
    con.execute("CREATE TABLE notes (t TEXT)")
    con.commit()
    con.close()
    before = other.read_bytes()
    for db, named in ((str(missing), "no factory database"), (f"sqlite:///{missing}", "no factory database"),
                      (str(other), "not a factory database"), ("mysql://x/y", "unknown scheme")):
        assert cli.main(["factory", "report", "--db", db]) == 2
        assert named in capsys.readouterr().err
    assert not missing.parent.exists() and other.read_bytes() == before and not (tmp_path / "mysql:").exists()
    with FactoryDB(str(tmp_path / "real.sqlite")):
        pass
    assert cli.main(["factory", "report", "--db", str(tmp_path / "real.sqlite"), "--since", "garbage"]) == 2
    assert "not an ISO date" in capsys.readouterr().err
    assert cli.main(["factory", "report", "--db", str(tmp_path / "real.sqlite"), "--since", "2026-11-01"]) == 0


# -- issue 22 item 14: a database written by others ------------------------------------------------
def _one(db_url: str, serial: str = "SN-1", reason: str = "ok", **kw) -> None:
    with FactoryDB(db_url) as db:
        db.record(Attempt(serial, "2026-01-02T03:04:05Z", "s", "0.2", "device", "9x6:0.03", True, reason, **kw))


@pytest.mark.parametrize("column, value", [("metrics", "{not json"), ("metrics", "[1, 2]"),
                                           ("calibration", "a calibration stored as text"),
                                           ("rms_stereo", "small"), ("passed", "yes")])
def test_a_report_names_rows_others_wrote_badly_and_reports_the_rest(tmp_path, capsys, column, value):
    url = str(tmp_path / "f.sqlite")
    _one(url, "SN-good", rms_stereo=0.2)
    _one(url, "SN-bad")
    with sqlite3.connect(url) as conn:
        conn.execute(f"UPDATE attempts SET {column} = ? WHERE unit_serial = 'SN-bad'", (value,))
    assert cli.main(["factory", "report", "--db", url, "--csv", str(tmp_path / "a.csv")]) == 0
    out, err = capsys.readouterr()
    assert "1 attempts" in out and "Traceback" not in err
    assert f"attempt 2: column {column}" in err and "left out of the report" in err
    assert [r["unit_serial"] for r in csv.DictReader((tmp_path / "a.csv").open())] == ["SN-good"]


def test_a_dropped_column_is_a_clean_error(tmp_path, capsys):
    url = str(tmp_path / "f.sqlite")
    _one(url)
    with sqlite3.connect(url) as conn:
        conn.execute("ALTER TABLE attempts DROP COLUMN reason")
    assert cli.main(["factory", "report", "--db", url]) == 2
    err = capsys.readouterr().err
    assert "cannot read the attempts" in err and "reason" in err and "Traceback" not in err


def test_a_locked_sqlite_file_is_reported_as_locked_not_as_foreign(tmp_path, capsys, monkeypatch):
    from stereocam.tools.factory import db as db_module

    url = str(tmp_path / "f.sqlite")
    _one(url)
    monkeypatch.setattr(db_module, "SQLITE_BUSY_S", 0.2)
    holder = sqlite3.connect(url, isolation_level=None)
    holder.execute("BEGIN EXCLUSIVE")
    try:
        assert cli.main(["factory", "report", "--db", url]) == 2
    finally:
        holder.execute("ROLLBACK")
        holder.close()
    err = capsys.readouterr().err
    assert "locked" in err and "not a factory database" not in err


def test_csv_export_defuses_spreadsheet_formulas(tmp_path):
    url = str(tmp_path / "f.sqlite")
    _one(url, '=HYPERLINK("http://evil.example","x")', reason="@SUM(A1)", rms_stereo=-0.5)
    assert cli.main(["factory", "report", "--db", url, "--csv", str(tmp_path / "a.csv")]) == 0
    (row,) = csv.DictReader((tmp_path / "a.csv").open())
    assert row["unit_serial"] == "'=HYPERLINK(\"http://evil.example\",\"x\")" and row["reason"] == "'@SUM(A1)"
    assert row["rms_stereo"] == "-0.5"  # a number is no formula


def _fresh_postgres_database(postgres_url: str, name: str) -> str:
    import psycopg

    with psycopg.connect(postgres_url, autocommit=True) as conn:
        conn.execute(f"DROP DATABASE IF EXISTS {name}")
        conn.execute(f"CREATE DATABASE {name}")
    head, _, query = postgres_url.partition("?")
    return f"{head.rpartition('/')[0]}/{name}" + (f"?{query}" if query else "")


@pytest.mark.parametrize("dialect", ["sqlite", "postgresql"])
def test_stations_creating_the_database_at_once_lose_no_record(tmp_path, request, dialect):
    import threading

    url = str(tmp_path / "new.sqlite") if dialect == "sqlite" else \
        _fresh_postgres_database(request.getfixturevalue("postgres_url"), "fresh_concurrent")
    n, errors = 30, []
    start = threading.Barrier(n)

    def station(i: int) -> None:
        try:
            start.wait()
            _one(url, f"SN-{i}")
        except Exception as exc:
            errors.append(exc)

    threads = [threading.Thread(target=station, args=(i,)) for i in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert not errors, errors[:3]
    with FactoryDB(url, create=False) as db:
        assert sorted(a.unit_serial for a in db.attempts()) == sorted(f"SN-{i}" for i in range(n))


def test_a_report_counts_each_failure_by_kind_and_shows_the_latest_whole():
    """Issue 20: the report cut every reason to its words before a colon ('calibration FAILED the gate')."""
    from stereocam.tools.factory.cli import report_doc, report_lines
    from stereocam.tools.factory.db import GATE_FAILED, Attempt

    def attempt(when: str, passed: bool, reason: str) -> Attempt:
        return Attempt("SN", f"2026-11-2{when}T10:00:00", "line-1", "0.2.0", "device", "9x6:0.025", passed, reason)

    rows = [attempt("1", False, GATE_FAILED + "stereo RMS 0.812 px > 0.5 px; baseline 0.2 m outside [0.05, 0.15]"),
            attempt("2", False, GATE_FAILED + "stereo RMS 0.634 px > 0.5 px"),
            attempt("3", False, "board not found in any of 14 pairs: is it in view and lit?"),
            attempt("4", True, "passed")]
    assert report_doc("db", rows)["failures"] == {"gate: stereo RMS": 2, "gate: baseline": 1,
                                                  "board not found in any of 14 pairs: is it in view and lit?": 1}
    lines = report_lines(rows)
    assert "failed    2 x  gate: stereo RMS  (latest: stereo RMS 0.634 px > 0.5 px)" in lines
    assert "failed    1 x  board not found in any of 14 pairs: is it in view and lit?" in lines


@pytest.mark.parametrize("csv_path, words", [("", "must name a file, got an empty value"),
                                             ("{tmp}/nodir/r.csv", "nodir is not a folder"),
                                             ("{tmp}/a-file/r.csv", "a-file is not a folder"),
                                             ("/proc/r.csv", "cannot write into directory '/proc'")])
def test_a_csv_path_that_cannot_be_written_is_refused_before_the_report(tmp_path, capsys, csv_path, words):
    """Audit: --csv was checked only after the report was printed; --csv '' said "Is a directory: '.'"."""
    url = str(tmp_path / "f.sqlite")
    _one(url)
    (tmp_path / "a-file").write_text("x")
    assert cli.main(["factory", "report", "--db", url, "--csv", csv_path.replace("{tmp}", str(tmp_path))]) == 2
    out, err = capsys.readouterr()
    assert "'--csv'" in err and words in err and "Traceback" not in err and not out  # no report: nothing done
