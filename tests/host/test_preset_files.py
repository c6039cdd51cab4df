"""Preset files: only a regular file of a preset's size is read (a FIFO never waited on, a device
never read), and a failed save keeps the preset it would have replaced, whole."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import stereocam
from stereocam import presets
from tests.support.hangs import returns_within


@pytest.fixture(scope="module")
def cam():
    camera = stereocam.open("sim://?seed=3", timeout=2.0)
    yield camera
    camera.close()


def test_load_preset_refuses_a_device_unread(cam):
    """Audit: /dev/zero was read without end (5.7 GiB after 6 s)."""
    before = cam.config()
    with pytest.raises(stereocam.ConfigError, match="/dev/zero is not a regular file"):
        returns_within(10, cam.load_preset, "/dev/zero")
    assert cam.config() == before


def test_load_preset_refuses_a_fifo_without_waiting_on_it(cam, tmp_path):
    """Audit: a FIFO named like a preset blocked load_preset for ever."""
    fifo = tmp_path / "p.json"
    os.mkfifo(fifo)
    with pytest.raises(stereocam.ConfigError, match=f"{fifo} is not a regular file"):
        returns_within(10, cam.load_preset, str(fifo))


def test_load_preset_refuses_a_file_larger_than_a_preset_can_be(cam, tmp_path):
    big = tmp_path / "big.json"
    big.write_bytes(b" " * (presets.MAX_PRESET_BYTES + 1))
    with pytest.raises(stereocam.ConfigError, match=f"{big} is .* bytes, more than"):
        cam.load_preset(big)


def _files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_a_save_that_fails_writing_keeps_the_previous_preset(cam, tmp_path):
    """Audit: a save over an existing preset that hit a full disk left it truncated."""
    keep = tmp_path / "keep.json"
    saved = cam.save_preset(keep)
    good = keep.read_bytes()
    code = ("import resource, signal, sys\n"
            "from stereocam import presets\n"
            "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
            "resource.setrlimit(resource.RLIMIT_FSIZE, (200, resource.RLIM_INFINITY))\n"
            "try:\n"
            f"    presets.write_preset(sys.argv[1], {saved!r})\n"
            "except presets.ConfigError as exc:\n"
            "    print(exc)\n")
    out = subprocess.run([sys.executable, "-c", code, str(keep)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and "cannot write preset" in out.stdout, out.stderr
    assert keep.read_bytes() == good and _files(tmp_path) == ["keep.json"]  # no temporary file left either
    assert presets.read_preset(keep) == saved


def test_a_save_that_fails_at_the_rename_keeps_the_previous_preset_and_its_mode(cam, tmp_path, monkeypatch):
    keep = tmp_path / "keep.json"
    cam.save_preset(keep)
    good = keep.read_bytes()
    os.chmod(keep, 0o640)

    def refuse(src: object, dst: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", refuse)
    with pytest.raises(stereocam.ConfigError, match="cannot write preset .*No space left"):
        cam.save_preset(keep)
    monkeypatch.undo()
    assert keep.read_bytes() == good and _files(tmp_path) == ["keep.json"]
    cam.save_preset(keep)  # replaced whole: the mode it had stays
    assert json.loads(keep.read_text())["format"] == presets.PRESET_FORMAT
    assert keep.stat().st_mode & 0o777 == 0o640
