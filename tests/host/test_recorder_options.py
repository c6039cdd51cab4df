"""Recorder options and record()'s progress are checked before a file is made or the camera is
asked: a ConfigError naming the option and its range, no file left, the same path free to retry."""
from __future__ import annotations

import logging

import numpy as np
import pytest

import stereocam
from stereocam.recording import Recorder, RecordingError, describe
from stereocam.recording.mcapwriter import MAX_CHUNK_BYTES, ChunkedWriter


@pytest.fixture(scope="module")
def cam():
    camera = stereocam.open("sim://?seed=3", timeout=3.0)
    camera.configure(width=320, height=240, num_disparities=32, block_size=11)
    yield camera
    camera.close()


BAD = [("threads", "x"), ("threads", 0), ("threads", -1), ("threads", 1.5), ("threads", 10**6), ("threads", True),
       ("queue_bytes", "x"), ("queue_bytes", None), ("queue_bytes", 0), ("queue_bytes", -5),
       ("chunk_bytes", 0), ("chunk_bytes", "x"), ("chunk_bytes", MAX_CHUNK_BYTES + 1), ("level", None)]


@pytest.mark.parametrize("option, value", BAD)
def test_a_bad_recorder_option_is_refused_before_a_file_is_made(cam, tmp_path, caplog, option, value):
    """Audit: threads="x" was a TypeError leaving an empty file; queue_bytes="x" logged tracebacks
    from the reader thread, then a StreamStalledError; threads=0, 10**6 and queue_bytes=0 were taken."""
    path = tmp_path / "r.mcap"
    with caplog.at_level(logging.ERROR):
        with pytest.raises(stereocam.ConfigError, match=f"{option if option != 'level' else 'zstd level'} must be "
                                                        f"an integer (from|of at least)"):
            cam.record(path, frames=2, **{option: value})
    assert not caplog.records and list(tmp_path.iterdir()) == [] and not cam.streaming
    with pytest.raises(stereocam.ConfigError, match=option):
        Recorder(path, describe(cam), **{option: value})
    assert list(tmp_path.iterdir()) == []


def test_progress_that_is_not_callable_is_refused_before_recording(cam, tmp_path):
    """Audit: progress=5 was a TypeError after recording had started, leaving a partial file."""
    path = tmp_path / "p.mcap"
    with pytest.raises(stereocam.ConfigError, match="progress must be a callable"):
        cam.record(path, frames=2, progress=5)
    assert list(tmp_path.iterdir()) == [] and not cam.streaming
    stats = cam.record(path, frames=2, threads=np.int64(1), queue_bytes=1 << 20)  # the path is free for a retry
    assert stats.frames == 2 and path.exists()


def test_a_recorder_that_cannot_write_its_head_leaves_no_file(cam, tmp_path, monkeypatch):
    unit = describe(cam)
    path = tmp_path / "r.mcap"

    def disk_full(*args: object, **kwargs: object) -> None:
        raise OSError(28, "No space left on device")

    with monkeypatch.context() as m:  # the MCAP header itself
        m.setattr(ChunkedWriter, "_record", disk_full)
        with pytest.raises(RecordingError, match="No space left"):
            Recorder(path, unit)
    assert list(tmp_path.iterdir()) == []
    with monkeypatch.context() as m:  # the unit's metadata, after the schemas and channels
        m.setattr(Recorder, "_write_unit", disk_full)
        with pytest.raises(RecordingError, match=f"cannot write {path}"):
            Recorder(path, unit)
    assert list(tmp_path.iterdir()) == []
    with monkeypatch.context() as m:  # anything else: raised as it is, the file still removed
        m.setattr(Recorder, "_write_unit", lambda self, unit: 1 / 0)
        with pytest.raises(ZeroDivisionError):
            Recorder(path, unit)
    assert list(tmp_path.iterdir()) == []
    Recorder(path, unit).close()  # the path is free again
    assert path.exists()
