"""Every documented exit code, through the real ``stereocam`` command (README, EXIT_CODES)."""
from __future__ import annotations

import subprocess
import sys

import pytest

from stereocam.tools.exit_codes import EXIT_BROKEN_PIPE, EXIT_CAMERA, EXIT_CODES, EXIT_OK, EXIT_USAGE

STEREOCAM = [sys.executable, "-m", "stereocam.tools.cli"]


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*STEREOCAM, *args], capture_output=True, text=True, timeout=180)


def test_the_codes_named_here_are_the_documented_ones():
    for code in (EXIT_OK, EXIT_CAMERA, EXIT_USAGE, 130, EXIT_BROKEN_PIPE):
        assert f"{code} " in EXIT_CODES


@pytest.mark.parametrize("args, code, said", [
    (["info", "sim://?seed=2"], EXIT_OK, ""),
    (["info", "socket://127.0.0.1:1"], EXIT_CAMERA, "error"),  # nothing listens there
    (["info", "socket://127.0.0.1"], EXIT_USAGE, "no port"),
    (["info", "sim://?seed=2", "--no-such-option"], EXIT_USAGE, "No such option"),
    (["record", "sim://?seed=2", "--out", "/nonexistent/x.mcap", "--frames", "1"], EXIT_USAGE, "--out"),
    (["record", "sim://?seed=2", "--out", "{tmp}/x.mcap", "--frames", "0"], EXIT_USAGE, "--frames"),
    (["record", "sim://?seed=2", "--out", "{tmp}/x.mcap"], EXIT_USAGE, "--frames"),
    (["record", "sim://?seed=2", "--out", "{tmp}/x.mcap", "--frames", "1", "--set", "block_size=16"], EXIT_USAGE,
     "OUT_OF_RANGE [block_size]"),  # a setting the camera refuses (ConfigRefused)
    (["conformance", "sim://?seed=2", "-k", "zzz"], EXIT_USAGE, "selects no check"),
    (["conformance", "sim://?seed=2", "-k", "("], EXIT_USAGE, "not a regular expression"),
    (["recording", "info", "/nonexistent/x.mcap"], EXIT_USAGE, "does not exist"),
    (["soak", "--seconds", "0"], EXIT_USAGE, "--seconds"),
    (["bench", "usb", "--read-size", "1000"], EXIT_USAGE, "multiple of 512"),
])
def test_documented_exit_code(args, code, said, tmp_path):
    r = _run(*(a.replace("{tmp}", str(tmp_path)) for a in args))
    assert r.returncode == code, r.stderr
    assert said in r.stderr and "Traceback" not in r.stderr
    assert not list(tmp_path.iterdir())  # a usage error leaves nothing behind


def test_output_closed_before_everything_was_written_is_141():
    """``stereocam info URL | head -1`` where head exits before info has written: 141, no traceback."""
    proc = subprocess.Popen([*STEREOCAM, "info", "sim://?seed=2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    proc.stdout.close()  # the reader is gone before the first line
    _, err = proc.communicate(timeout=180)
    assert proc.returncode == EXIT_BROKEN_PIPE and "Traceback" not in err, err
