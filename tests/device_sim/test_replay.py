"""Replay as a device: through ``replay://`` and a served simulator, the host gets the recorded unit
and byte-identical planes, sequence numbers and device timestamps; seeking reads only the index."""
from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np
import pytest

import stereocam
from stereocam.stereo import Matcher
from stereocam.stereo.engines import params_from_config
from stereocam.recording.reader import Recording
from stereocam.tools.bench.record import synthetic_recording
from tests.support.hangs import terminated

N = 8


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("replay") / "run.mcap"
    with stereocam.open("sim://?seed=6", timeout=3.0) as cam:
        cam.configure(width=320, height=240, num_disparities=32, block_size=11, fps=15)
        cam.record(path, frames=N)
    with Recording(path) as rec:
        return path, list(rec.captures()), rec.calibration


def _same(frames, captures):
    for f, c in zip(frames, captures, strict=True):
        assert (f.sequence, f.trigger_id, f.device_time_us) == (c.info.sequence, c.info.trigger_id,
                                                                  c.info.device_time_us)
        assert f.left.tobytes() == c.left.tobytes() and f.right.tobytes() == c.right.tobytes()
        assert f.disparity.tobytes() == c.disparity.tobytes()


def test_replay_url_is_the_recorded_unit(recording):
    path, caps, calibration = recording
    with stereocam.open(f"replay://{path}?speed=fast", timeout=3.0) as cam:
        info = cam.info()
        assert (info.model, info.serial) == ("STOC-SIM", "SIM00006")
        assert cam.config()["block_size"] == 11 and cam.config()["width"] == 320
        assert cam.read_calibration().body == calibration.body
        cam.start()
        frames = [cam.get_frame(timeout=10.0) for _ in range(N)]
        _same(frames, caps)
        with pytest.raises(stereocam.EndOfRecordingError, match="end of recording") as end:  # played once
            cam.get_frame(timeout=5.0)
        assert end.value.path == str(path) and str(path) in str(end.value)
        assert frames[0].geometry.calibration_id == calibration.calibration_id and cam.geometry_mismatches == 0


def test_iterating_a_replay_stops_after_its_last_frame(recording):
    """The end of a recording played once ends the iteration (it was a StreamStalledError that spoke
    of software triggers); started again, it plays again."""
    path, caps, _ = recording
    with stereocam.open(f"replay://{path}?speed=fast", timeout=3.0) as cam:
        for _ in range(2):
            cam.start()
            _same(list(cam), caps)
            cam.stop()


def test_a_recording_of_a_triggered_head_replays_at_its_recorded_pace_with_its_trigger_ids(tmp_path):
    """A head recorded on an external trigger (here its own: the trigger master) replays in free
    run: the recording paces it, each frame keeps the trigger id it was captured on."""
    path = tmp_path / "head.mcap"
    with stereocam.open("sim://?seed=8", timeout=3.0) as cam:
        cam.configure(width=160, height=120, num_disparities=16, block_size=9, fps=20,
                      trigger_mode=int(stereocam.TriggerMode.EXTERNAL), trigger_output=1)
        cam.record(path, frames=5)
    with Recording(path) as rec:
        caps = list(rec.captures())
        assert rec.config["trigger_mode"] == stereocam.TriggerMode.EXTERNAL
    with stereocam.open(f"replay://{path}?speed=fast", timeout=3.0) as cam:
        config = cam.config()
        assert (config["trigger_mode"], config["trigger_output"], config["width"]) == (0, 0, 160)
        cam.start()
        frames = [cam.get_frame(timeout=10.0) for _ in range(5)]
    _same(frames, caps)
    assert [f.trigger_id for f in frames] == [c.info.trigger_id for c in caps] and frames[0].trigger_id > 0


def test_a_software_trigger_takes_the_next_recorded_capture_numbered_as_triggered(recording, tmp_path):
    """`stereocam capture replay://FILE` software-triggers: each TRIGGER gets the next recorded
    capture at once, its planes as recorded, its ids those TRIGGERED gave, its time the replay's."""
    path, caps, _ = recording
    with stereocam.open(f"replay://{path}", timeout=3.0) as cam:
        cam.set_trigger_mode("software")
        cam.start()
        got = []
        for _ in range(3):
            tid = cam.trigger()
            f = cam.get_frame(timeout=10.0)
            assert f.trigger_id == tid
            got.append(f)
    assert [f.left.tobytes() for f in got] == [c.left.tobytes() for c in caps[:3]]
    assert [f.disparity.tobytes() for f in got] == [c.disparity.tobytes() for c in caps[:3]]
    seqs, times = [f.sequence for f in got], [f.device_time_us for f in got]
    assert seqs == sorted(set(seqs)) and times == sorted(set(times))
    out = tmp_path / "shots"
    r = subprocess.run([sys.executable, "-m", "stereocam.tools.cli", "capture", f"replay://{path}", "--count", "2",
                        "--out", str(out)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert len(list(out.glob("*left*.png"))) == 2


def test_start_index_and_loop(recording):
    path, caps, _ = recording
    with stereocam.open(f"replay://{path}?speed=fast&start={N - 2}&loop=1", timeout=3.0) as cam:
        cam.start()
        frames = [cam.get_frame(timeout=10.0) for _ in range(5)]
    _same(frames, [caps[N - 2], caps[N - 1], caps[N - 2], caps[N - 1], caps[N - 2]])


def test_recorded_speed(recording):
    path, caps, _ = recording
    with stereocam.open(f"replay://{path}", timeout=3.0) as cam:
        cam.start()
        arrivals = []
        for _ in range(4):
            cam.get_frame(timeout=10.0)
            arrivals.append(time.monotonic())
    span = (caps[3].info.device_time_us - caps[0].info.device_time_us) / 1e6
    assert arrivals[3] - arrivals[0] >= 0.9 * span  # not sooner than recorded (later only under load)


def test_other_matching_config_rematches_on_board(recording):
    path, caps, _ = recording
    with stereocam.open(f"replay://{path}?speed=fast", timeout=3.0) as cam:
        cam.configure(block_size=21)
        cam.start()
        f = cam.get_frame(timeout=10.0)
    c = caps[0]
    assert f.left.tobytes() == c.left.tobytes() and f.sequence == c.info.sequence
    assert not np.array_equal(f.disparity, c.disparity)
    with Recording(path) as rec:
        cfg = rec.config | {"block_size": 21}
    params = params_from_config(cfg)
    expected = Matcher(c.left.shape, params).match(c.left, c.right)
    assert np.array_equal(f.disparity, expected)


def test_served_replay_over_tcp(recording):
    path, caps, _ = recording
    proc = subprocess.Popen([sys.executable, "-m", "stereocam.device_sim", "--serve", "tcp:127.0.0.1:0", "--replay",
                             str(path), "--fast", "--start", "3"], stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        url = proc.stdout.readline().strip()
        assert url.startswith("socket://")
        with stereocam.open(url, timeout=3.0) as cam:
            assert cam.info().serial == "SIM00006"
            cam.start()
            frames = [cam.get_frame(timeout=10.0) for _ in range(N - 3)]
        _same(frames, caps[3:])
    finally:
        terminated(proc, 10)


def _bytes_read() -> int:
    with open("/proc/self/io") as f:
        return int(next(line for line in f if line.startswith("rchar")).split()[1])


def test_seek_reads_only_the_index_and_one_chunk(tmp_path):
    path = tmp_path / "long.mcap"
    synthetic_recording(path, 10_000)
    with Recording(path) as rec:
        assert len(rec) == 10_000
        biggest = max(c.chunk_length for c in rec.summary.chunk_indexes)
        assert path.stat().st_size > 20 * biggest
        for i in (9_999, 5_000, 17):
            before = _bytes_read()
            cap = rec.capture(i)
            assert cap.info.sequence == i + 1 and cap.info.device_time_us == 1_000_000 + i * 33_333
            assert _bytes_read() - before < 2 * biggest


@pytest.mark.parametrize("jump_us", [10**11, 2**63])
def test_hostile_device_times_neither_kill_nor_stall_the_replay(tmp_path, jump_us):
    """Issue 22.8: recorded device times that jump by 10^11 µs (28 h) or 2^63 µs: every frame still
    plays (a jump past the pacing limit restarts the pacing) and close() ends the capture thread."""
    import threading

    from stereocam.recording import Recorder, UnitDescription

    path = tmp_path / "hostile.mcap"
    times = [1_000_000, 1_033_333, 1_033_333 + jump_us, 1_066_666 + jump_us, 1_100_000 + jump_us]
    plane = np.zeros((48, 64), np.uint8)
    unit = UnitDescription({"model": "STOC-SYNTH", "serial": "SYNTH0002", "firmware_version": "0",
                            "protocol_version": "1.1"}, {"width": 64, "height": 48, "fps": 30}, None)
    with Recorder(path, unit) as rec:
        for i, t in enumerate(times):
            rec.put_wait(stereocam.Frame(i + 1, 0, min(t, 2**64 - 1), 100.0 + i / 30, plane, plane,
                                         np.zeros((48, 64), np.int16), 4000, 0, 64, 48, True,
                                         stereocam.DisparityFormat(16, 0, 64, -16),
                                         stereocam.StereoGeometry(60.0, 32.0, 24.0, 0.1)))
    before = set(threading.enumerate())
    cam = stereocam.open(f"replay://{path}", timeout=3.0)
    try:
        cam.start()
        frames = [cam.get_frame(timeout=5.0) for _ in times]
        assert [f.device_time_us for f in frames] == times
    finally:
        t0 = time.monotonic()
        cam.close()
    left = [t for t in set(threading.enumerate()) - before if t.name == "capture"]
    for t in left:
        t.join(timeout=max(0.0, 5.0 - (time.monotonic() - t0)))
    assert not any(t.is_alive() for t in left)
