"""Bad input to record and recording export (rematch's: test_rematch.py): a clear one-line message
and the documented exit code (2 usage, 1 runtime), never a traceback, nothing left that looks done."""
from __future__ import annotations

from pathlib import Path

import pytest

import stereocam
from stereocam.tools import cli

N = 3


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("in") / "run.mcap"
    with stereocam.open("sim://?seed=11", timeout=3.0) as cam:
        cam.configure(width=320, height=240, num_disparities=32, block_size=11)
        cam.record(path, frames=N)
    return path


def _clean(err: str) -> str:
    assert "Traceback" not in err and "Compute Failed" not in err, err
    return err


@pytest.mark.parametrize("args", [["--start", "2", "--stop", "1"], ["--start", "1", "--stop", "1"]])
def test_export_stop_not_after_start_is_a_usage_error(recording, tmp_path, capsys, args):
    assert cli.main(["recording", "export", str(recording), "--out", str(tmp_path / "x"), *args]) == 2
    err = _clean(capsys.readouterr().err)
    assert "--stop" in err and "after --start" in err and not (tmp_path / "x").exists()


@pytest.mark.parametrize("args, said", [(["--start", "5"], "--start 5 selects no frame"),
                                        (["--start", "3", "--stop", "9"], "--start 3 --stop 9 selects no frame")])
def test_export_of_no_frame_fails_naming_the_recordings_range(recording, tmp_path, capsys, args, said):
    """Audit: "0 frames exported", exit 0."""
    assert cli.main(["recording", "export", str(recording), "--out", str(tmp_path / "x"), *args]) == 1
    captured = capsys.readouterr()
    err = _clean(captured.err)
    assert said in err and str(recording) in err and f"frames 0..{N - 1}" in err and " s)" in err
    assert "exported" not in captured.out and not (tmp_path / "x").exists()
    assert cli.main(["recording", "export", str(recording), "--out", str(tmp_path / "x"), "--start", "2",
                     "--stop", "9"]) == 0  # a range reaching past the end exports what there is
    assert "1 frames exported" in capsys.readouterr().out


def test_record_without_a_frame_fails_saying_why_and_keeps_no_file(tmp_path, capsys):
    """Audit: --set trigger_mode=1 (software: nothing triggers it) gave "0 frames, 0.0 MB", exit 0."""
    out = tmp_path / "x.mcap"
    assert cli.main(["record", "sim://?seed=11", "--out", str(out), "--frames", "1", "--set", "trigger_mode=1",
                     "--set", "width=320", "--set", "height=240", "--quiet"]) == 1
    captured = capsys.readouterr()
    err = _clean(captured.err)
    assert "no frame arrived" in err and "software-trigger mode" in err and "not kept" in err
    assert len(err.strip().splitlines()) == 1 and "0 frames" not in captured.out
    assert not out.exists()  # an empty recording is removed: the same --out works on the next try


def test_sdk_record_without_a_frame_is_a_stream_stalled_error(tmp_path):
    path = tmp_path / "x.mcap"
    with stereocam.open("sim://?seed=11", timeout=3.0) as cam:
        cam.configure(width=320, height=240, trigger_mode=2)  # external: no pulse comes in-process
        with pytest.raises(stereocam.StreamStalledError, match="external trigger pulses"):
            cam.record(path, seconds=0.3)
        assert not path.exists() and not cam.streaming


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc (takes no file)")
def test_record_into_a_folder_that_takes_no_file_is_a_usage_error(capsys):
    """Audit: --out /proc/out.mcap exited 1 after opening the camera; a path that cannot be written is usage."""
    assert cli.main(["record", "socket://127.0.0.1:1", "--out", "/proc/out.mcap", "--frames", "1"]) == 2
    err = _clean(capsys.readouterr().err)
    assert "--out" in err and "cannot write into directory '/proc'" in err
