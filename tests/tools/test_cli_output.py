"""What the stereocam command writes besides its results: stereocam's log lines at -v / -vv, other
libraries' only when asked (--log-level NAME=LEVEL), progress bars only on a terminal."""
from __future__ import annotations

import fcntl
import logging
import os
import pty
import struct
import subprocess
import sys
import termios
import time

import pytest

from stereocam.tools import cli
from stereocam.tools.logs import LogLevels, parse_levels

STEREOCAM = [sys.executable, "-m", "stereocam.tools.cli"]


def _record(name: str, level: int) -> logging.LogRecord:
    return logging.LogRecord(name, level, __file__, 1, "message", None, None)


def test_levels_from_verbosity_and_names():
    assert parse_levels(0, ()).own == logging.WARNING
    assert parse_levels(1, ()).own == logging.INFO and parse_levels(5, ()).own == logging.DEBUG
    levels = parse_levels(2, ("error", "distributed=info", "PIL=Debug"))
    assert levels.own == logging.ERROR  # a bare level overrides -v
    assert levels.named == {"distributed": logging.INFO, "PIL": logging.DEBUG}
    for bad in ("loud", "x=loud", "=INFO", "distributed="):
        with pytest.raises(ValueError, match="NAME=LEVEL"):
            parse_levels(0, (bad,))


def test_other_libraries_stay_at_warnings_unless_asked():
    quiet = LogLevels(logging.DEBUG)
    assert quiet.allows(_record("stereocam.link", logging.DEBUG))
    assert not LogLevels(logging.INFO).allows(_record("stereocam.link", logging.DEBUG))
    for name in ("matplotlib.font_manager", "distributed.scheduler", "dask", "urllib3", "PIL.PngImagePlugin", "numba"):
        assert not quiet.allows(_record(name, logging.INFO)) and quiet.allows(_record(name, logging.WARNING))
    asked = LogLevels(logging.WARNING, {"distributed": logging.INFO})
    assert asked.allows(_record("distributed.scheduler", logging.INFO))
    assert not asked.allows(_record("distributed.scheduler", logging.DEBUG))
    assert not asked.allows(_record("distributedx", logging.INFO))  # a logger, not a prefix of a name
    assert asked.lowest == logging.INFO and LogLevels(logging.DEBUG).lowest == logging.DEBUG


def test_a_command_run_in_process_leaves_logging_as_found(capsys):
    root = logging.getLogger()
    level, handlers = root.level, list(root.handlers)
    assert cli.main(["-vv", "--log-level", "PIL=INFO", "list", "--json"]) == 0
    assert "DEBUG stereocam.cli" in capsys.readouterr().err
    assert root.level == level and root.handlers == handlers


def _capture(tmp_path, *options: str, stderr=subprocess.PIPE) -> subprocess.Popen:
    return subprocess.Popen([*STEREOCAM, *options, "capture", "sim://?seed=3", "--out", str(tmp_path), "--count", "2"],
                            stdout=subprocess.PIPE, stderr=stderr, text=True)


def test_vv_shows_stereocam_lines_and_not_matplotlib(tmp_path):
    _, err = _capture(tmp_path / "a", "-vv").communicate(timeout=180)
    assert "DEBUG stereocam.cli: stereocam " in err and "matplotlib" not in err, err
    _, err = _capture(tmp_path / "b", "-vv", "--log-level", "matplotlib=DEBUG").communicate(timeout=180)
    assert "DEBUG matplotlib" in err


def test_progress_bars_only_on_a_terminal(tmp_path):
    proc = _capture(tmp_path / "piped")
    _, err = proc.communicate(timeout=180)
    assert proc.returncode == 0 and "\r" not in err and "frame/s" not in err, err
    controller, terminal = pty.openpty()
    fcntl.ioctl(terminal, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # a terminal 100 wide
    proc = _capture(tmp_path / "tty", stderr=terminal)
    os.close(terminal)
    seen, deadline = b"", time.monotonic() + 180
    while time.monotonic() < deadline:
        try:
            chunk = os.read(controller, 4096)
        except OSError:  # the command closed its end
            break
        if not chunk:
            break
        seen += chunk
    os.close(controller)
    assert proc.wait(timeout=60) == 0
    assert b"2/2" in seen and b"\r" in seen, seen
