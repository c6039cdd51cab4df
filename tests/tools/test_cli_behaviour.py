"""The stereocam command behaves like the tools users know: help, exit codes, clean errors, pipes,
Ctrl-C, validation before the camera is touched, the camera left as found, served simulators listed."""
from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

import stereocam
from stereocam.device_sim.process import ServedSimulator
from stereocam.tools.cli import COMMANDS
from tests.tools.test_cli import stereocam as run




def _popen(*args: str) -> subprocess.Popen:
    """The CLI as a terminal starts it: with Ctrl-C's default action, even when this suite runs in
    a non-interactive shell's background job (which starts everything with SIGINT ignored)."""
    return subprocess.Popen([sys.executable, "-m", "stereocam.tools.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def test_version():
    r = run("--version")
    assert r.returncode == 0 and r.stdout.strip() == f"stereocam {stereocam.__version__}"


@pytest.mark.parametrize("name", list(COMMANDS))
def test_every_help_is_plain_and_names_itself(name):
    r = run(name, "--help")
    assert r.returncode == 0, r.stderr
    assert f"stereocam {name}" in r.stdout
    assert "Exit codes" in r.stdout and "``" not in r.stdout


def test_bench_help_lists_every_mode():
    out = run("bench", "--help").stdout
    for mode in ("protocol", "transport", "usb", "matching", "calibration", "all"):
        assert re.search(rf"^ +{mode} +\w", out, re.M), f"{mode} is not described"


def test_demo_options_have_help_and_defaults():
    out = run("demo", "--help").stdout
    assert "How long to stream.  [default: 4.0" in out and "Frame rate to ask for.  [default: 15" in out


def test_info_json_names_enums_and_shows_calibration():
    r = run("info", "sim://?seed=2", "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["serial"] == "SIM00002" and doc["config"]["trigger_mode"] == "free_run"
    assert doc["config"]["outputs"] == "left+right+disparity"
    assert (doc["config"]["algorithm"], doc["config"]["pre_filter_type"], doc["config"]["rectify"]) == (
        "block_matching", "xsobel", "rectified")
    assert doc["calibration"]["source"] == "factory" and doc["calibration"]["id"] > 0
    assert "frames_sent" in doc["counters"] or doc["counters"]


def test_broken_pipe_is_a_documented_exit_not_a_traceback():
    proc = _popen("info", "sim://?seed=2")
    proc.stdout.close()  # like `| head` having exited before the first line
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 141 and "Traceback" not in err, err


def test_ctrl_c_is_a_clean_exit_130(tmp_path):
    proc = _popen("demo", "--seconds", "60", "--out", str(tmp_path))
    assert proc.stdout.readline().startswith("camera:")  # the camera is open: the demo is under way
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "interrupted" in err and "Traceback" not in err, err


@pytest.mark.parametrize("command", ["capture", "demo"])
def test_bad_out_is_refused_before_the_camera_is_touched(command, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    url = ["socket://127.0.0.1:1"] if command == "capture" else []  # unreachable: would fail with 1 if opened
    r = run(command, *url, "--out", str(blocker / "sub"))
    assert r.returncode == 2 and "--out" in r.stderr and "Traceback" not in r.stderr, r.stderr


@pytest.mark.parametrize("count", ["0", "-3"])
def test_capture_count_must_be_positive(count, tmp_path):
    r = run("capture", "socket://127.0.0.1:1", "--out", str(tmp_path), "--count", count)
    assert r.returncode == 2 and "--count" in r.stderr and not list(tmp_path.iterdir())


def test_capture_leaves_the_camera_as_found(tmp_path):
    with ServedSimulator("tcp:127.0.0.1:0", seed=4) as server:
        r = run("capture", server.url, "--out", str(tmp_path), "--count", "2")
        assert r.returncode == 0, r.stderr  # its progress bar: tests/tools/test_cli_output.py
        assert len(list(tmp_path.glob("*_left.png"))) == 2
        with stereocam.open(server.url, timeout=2.0) as cam:
            assert cam.config()["trigger_mode"] == stereocam.TriggerMode.FREE_RUN
            cam.configure(width=320, height=240, num_disparities=32, block_size=11)
            cam.start()
            assert cam.get_frame(timeout=30).sequence >= 0


def test_log_level_reaches_logging():
    r = run("--log-level", "debug", "info", "socket://127.0.0.1:1")
    assert r.returncode == 1 and "DEBUG stereocam.cli: info failed" in r.stderr
    assert "Traceback" in r.stderr  # debug logs keep the context; the default level shows one line
    r = run("info", "socket://127.0.0.1:1")
    assert r.returncode == 1 and "Traceback" not in r.stderr


def test_list_finds_simulators_served_over_tcp_and_pty():
    with ServedSimulator("tcp:127.0.0.1:0", seed=11) as tcp, ServedSimulator("pty", seed=12) as pty:
        r = run("list", "--json")
        assert r.returncode == 0, r.stderr
        found = {e["url"]: e for e in json.loads(r.stdout)}
        assert found[tcp.url]["serial"] == "SIM00011" and found[tcp.url]["transport"] == "tcp"
        assert found[pty.url]["serial"] == "SIM00012" and found[pty.url]["transport"] == "pty"
        assert "SIM00011" in run("list").stdout
    urls = [e["url"] for e in json.loads(run("list", "--json").stdout)]
    assert tcp.url not in urls and pty.url not in urls


def test_sim_url_with_an_unknown_serial_does_not_make_a_simulator():
    with pytest.raises(stereocam.TransportError, match="NOPE.*not found"):
        stereocam.open("sim://?serial=NOPE")
    r = run("info", "sim://?serial=NOPE")
    assert r.returncode == 1 and "not found" in r.stderr and "Traceback" not in r.stderr
    with stereocam.open("sim://?seed=3&serial=NEW-1") as cam:  # a seed makes one, with that serial
        assert cam.info().serial == "NEW-1"


def test_capture_and_demo_print_json(tmp_path):
    r = run("capture", "sim://?seed=3", "--out", str(tmp_path / "c"), "--count", "2", "--json")
    assert r.returncode == 0, r.stderr
    saved = json.loads(r.stdout)
    assert len(saved) == 2 and all(Path(f).exists() for s in saved for f in s["files"].values())
    r = run("demo", "--seconds", "1", "--out", str(tmp_path / "d"), "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["frames"] >= 1 and doc["fps_asked"] == 15 and ("keep up" in doc["note"] or "kept up" in doc["note"])
    assert doc["dropped"] == doc["device_dropped"] + doc["host_queue_dropped"] + doc["other_dropped"]


@pytest.mark.parametrize("first, last, frames, device, queue, split", [
    (10, 19, 10, 0, 0, (0, 0, 0, 0)),
    (10, 29, 10, 7, 2, (10, 7, 2, 1)),
    (10, 29, 10, 351, 0, (10, 10, 0, 0)),  # a device count from before the run cannot exceed what is missing
    (10, 29, 10, 3, 50, (10, 0, 10, 0))])
def test_demo_drops_add_up_to_their_total(first, last, frames, device, queue, split):
    """Issue 20: `demo --fps 120` printed dropped=343 beside device_dropped=351 (counted since boot)."""
    from stereocam.tools.demo.cli import Drops

    drops = Drops.of(first, last, frames, device, queue)
    assert (drops.total, drops.device, drops.host_queue, drops.other) == split


def test_simulators_served_without_a_seed_have_unique_serials():
    """Issue 20: every `stereocam sim` without --seed was SIM00000, so `list` showed duplicates."""
    with ServedSimulator("tcp:127.0.0.1:0", seed=None) as a, ServedSimulator("tcp:127.0.0.1:0", seed=None) as b:
        serials = []
        for url in (a.url, b.url):
            with stereocam.open(url, timeout=3.0) as cam:
                serials.append(cam.info().serial)
        listed = [e.serial for e in stereocam.list_devices() if e.url in (a.url, b.url)]
    assert len(set(serials)) == 2 and sorted(listed) == sorted(serials)
