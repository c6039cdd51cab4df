"""Recordings checked by independent readers: mcap's summary and index, rosbags' ROS 2 types."""
from __future__ import annotations

import json


import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

import stereocam
from stereocam.protocol.params import defaults
from stereocam.protocol.rectification import stereo_rectify
from stereocam.recording import Recorder, RecordingError, describe, schemas
from stereocam.recording.reader import Recording
from stereocam.tools import cli

N = 6


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A recording of a simulator, written by a Recorder, and the frames it was given."""
    path = tmp_path_factory.mktemp("rec") / "run.mcap"
    with stereocam.open("sim://?seed=3", timeout=3.0) as cam:
        cam.configure(width=320, height=240, num_disparities=32, block_size=11, fps=30)
        cam.start()
        frames = [cam.get_frame(timeout=30.0) for _ in range(N)]
        cam.stop()
        unit = describe(cam)
    with Recorder(path, unit, chunk_bytes=256 << 10) as rec:
        for f in frames:
            assert rec.put(f)
    return path, frames, unit


def test_mcap_summary_and_index(recorded):
    path, frames, _ = recorded
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary.statistics.message_count == N * len(schemas.TOPICS)
        assert len(summary.chunk_indexes) > 1
        by_topic = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
        assert by_topic == {t: N for t in schemas.TOPICS}
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
        assert reader.get_header().profile == "ros2"
        # reading through the index from the 4th capture's stamp gives exactly the last three captures
        t3 = sorted({m.log_time for _, _, m in reader.iter_messages(topics=[schemas.CAPTURE])})[3]
        seqs = [m.sequence for _, _, m in reader.iter_messages(topics=[schemas.LEFT], starting_at=t3)]
        assert seqs == [f.sequence for f in frames[3:]]


def test_rosbags_reads_ros2_messages(recorded):
    path, frames, unit = recorded
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        msgs: dict[str, list] = {}
        for con, _, raw in reader.messages():
            msgs.setdefault(con.topic, []).append((con.msgtype, reader.deserialize(raw, con.msgtype)))
    types = {t: {m[0] for m in v} for t, v in msgs.items()}
    assert types[schemas.LEFT] == {"sensor_msgs/msg/Image"}
    assert types[schemas.DISPARITY_TOPIC] == {"stereo_msgs/msg/DisparityImage"}
    assert types[schemas.LEFT_INFO] == {"sensor_msgs/msg/CameraInfo"}
    geometry = stereo_rectify(unit.calibration.calibration.scaled(320, 240))
    for i, f in enumerate(frames):
        left = msgs[schemas.LEFT][i][1]
        right = msgs[schemas.RIGHT][i][1]
        assert left.encoding == "mono8" and (left.height, left.width, left.step) == (240, 320, 320)
        assert np.array_equal(left.data.reshape(240, 320), f.left)
        assert np.array_equal(right.data.reshape(240, 320), f.right)
        disp = msgs[schemas.DISPARITY_TOPIC][i][1]
        px = disp.image.data.view("<f4").reshape(240, 320)
        assert np.array_equal(np.rint(px * 16).astype(np.int16), f.disparity)
        assert disp.delta_d == pytest.approx(1 / 16) and disp.f == pytest.approx(f.geometry.focal_px)
        info = msgs[schemas.CAPTURE][i][1]
        assert (info.sequence, info.device_time_us, info.status) == (f.sequence, f.device_time_us, "complete")
        stamp = info.header.stamp.sec * 10**9 + info.header.stamp.nanosec
        assert stamp == left.header.stamp.sec * 10**9 + left.header.stamp.nanosec
        rinfo = msgs[schemas.RIGHT_INFO][i][1]
        np.testing.assert_allclose(rinfo.p.reshape(3, 4), geometry.P2)
        assert rinfo.p[3] == pytest.approx(-geometry.focal_px * geometry.baseline_m)


def test_reader_seek_and_unit(recorded):
    path, frames, unit = recorded
    with Recording(path) as rec:
        assert len(rec) == N
        assert rec.device["serial"] == "SIM00003" and rec.config["width"] == 320
        assert rec.calibration.body == unit.calibration.body
        cap = rec.capture(4)
        assert cap.info.sequence == frames[4].sequence
        assert np.array_equal(cap.disparity, frames[4].disparity) and cap.disparity.dtype == np.int16
        assert [c.info.sequence for c in rec.captures(2, 5)] == [f.sequence for f in frames[2:5]]
        with pytest.raises(IndexError):
            rec.capture(N)


def test_recorder_drops_are_counted_and_stored(tmp_path, recorded):
    _, frames, unit = recorded
    path = tmp_path / "drops.mcap"
    rec = Recorder(path, unit, queue_bytes=1)  # room for one capture at a time
    accepted = sum(rec.put(frames[i % N]) for i in range(200))
    stats = rec.close()
    assert stats.recorder_dropped == 200 - accepted > 0
    with Recording(path) as r:
        assert len(r) == accepted
        assert int(r.metadata["stereocam.summary"]["recorder_dropped"]) == stats.recorder_dropped
        last = r.capture(-1).info
        assert 0 < last.recorder_dropped <= stats.recorder_dropped


def test_camera_record_and_tools(tmp_path, capsys, device_url):
    """Camera.record against every transport (or --device), read back by the recording tools."""
    path = tmp_path / "cam.mcap"
    with stereocam.open(device_url, timeout=3.0) as cam:
        cam.configure(**{**defaults(), "width": 320, "height": 240, "num_disparities": 32, "block_size": 11})
        cam_info, stored = cam.info(), cam.read_calibration()
        serial = cam_info.serial
        stats = cam.record(path, frames=4)
    assert stats.frames == 4 and stats.recorder_dropped == 0
    assert cli.main(["recording", "info", str(path)]) == 0
    out = out_text = capsys.readouterr().out
    assert serial in out and "frames    4" in out and "stereo_msgs/msg/DisparityImage" in out
    assert cli.main(["recording", "info", str(path), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["unit"]["serial"] == serial and doc["frames"] == 4 and doc["drops"]["recorder_dropped"] == 0
    assert doc["topics"]["/stereo/disparity"]["messages"] == 4
    assert (doc["calibration"] is None) == (stored is None)
    if stored is not None:
        assert doc["calibration"]["lens_model"] == stored.calibration.lens_model
        assert doc["calibration"]["id"] == stored.calibration_id  # a number, as every number in the JSON
        assert f"id {stored.calibration_id:08x}:" in out_text  # text: 8 hex digits, as info and calibrate print it
        assert doc["unit"]["capabilities"] == cam_info.capabilities
        assert doc["unit"]["protocol_version"] == "%d.%d" % cam_info.protocol_version
    assert cli.main(["recording", "export", str(path), "--out", str(tmp_path / "x"), "--stop", "2"]) == 0
    names = sorted(p.name for p in (tmp_path / "x").iterdir())
    assert names[:5] == ["frame000000_disparity.npy", "frame000000_disparity.png", "frame000000_left.png",
                         "frame000000_points.ply", "frame000000_right.png"] and len(names) == 10
    with Recording(path) as rec:
        assert np.array_equal(np.load(tmp_path / "x" / "frame000001_disparity.npy"), rec.capture(1).disparity)


def test_bad_files_give_typed_errors(tmp_path):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    with pytest.raises(RecordingError):
        Recording(junk)
    with pytest.raises(stereocam.StereoCamError):
        Recording(tmp_path / "missing.mcap")
    with stereocam.open("sim://?seed=1") as cam, pytest.raises(RecordingError):
        cam.record(tmp_path / "nodir" / "x.mcap", frames=1)


def test_a_damaged_chunk_is_a_typed_error_naming_the_frame(tmp_path, recorded, capsys):
    """Bytes flipped inside a compressed chunk (a bad disk, a hostile file): reading the frames in it
    raises RecordingError naming the file and frame; the tools print it and exit 1, no traceback."""
    path, frames, _ = recorded
    bad = tmp_path / "bad.mcap"
    data = bytearray(path.read_bytes())
    with Recording(path) as rec:
        chunk = max(rec.summary.chunk_indexes, key=lambda c: c.chunk_start_offset)  # the last frame's
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    for i in range(middle, middle + 64):
        data[i] ^= 0x5A
    bad.write_bytes(bytes(data))
    with Recording(bad) as rec:
        assert rec.capture(0).info.sequence == frames[0].sequence  # the chunks before it still read
        with pytest.raises(RecordingError, match=r"bad\.mcap: frame \d+ cannot be read"):
            list(rec.captures())

    assert cli.main(["recording", "export", str(bad), "--out", str(tmp_path / "x")]) == 1
    err = capsys.readouterr().err
    assert "cannot be read" in err and "Traceback" not in err
    with stereocam.open(f"replay://{bad}?speed=fast", timeout=2.0) as cam:  # replayed as a device
        cam.start()
        got = []
        with pytest.raises(stereocam.EndOfRecordingError):  # played once: the end, after every readable frame
            while True:
                got.append(cam.get_frame(timeout=3.0).sequence)
        assert cam.status().counters["frames_sent"] == len(got)
        cam.stop()
        cam.start()  # the device went on: a new stream plays from the start again
        assert cam.get_frame(timeout=5.0).sequence == frames[0].sequence
    readable = [f.sequence for f in frames][:len(got)]
    assert got == readable and 0 < len(got) < len(frames)  # the damaged frames skipped, never sent damaged


@pytest.mark.parametrize("n", [0, 1, 3, 4, 7, 4096])
def test_spliced_cdr_equals_the_library_encoding(n):
    rng = np.random.default_rng(n)
    blob = rng.integers(0, 256, n, np.uint8).tobytes()
    for name, body, slot in (
            (schemas.IMAGE, {"header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "odd"}, "height": 1,
                             "width": n, "encoding": "mono8", "step": n}, None),
            (schemas.DISPARITY, {"header": {"frame_id": "x"}, "image": {"encoding": "32FC1"}, "f": 1.5, "t": 0.1,
                                 "valid_window": {"width": 3}, "min_disparity": -1.0, "max_disparity": 63.0,
                                 "delta_d": 0.0625}, "image")):
        encode = schemas.encoder(name)
        target = body[slot] if slot else body
        spliced = b"".join(schemas.encode_with_blob(encode, body, target, memoryview(blob)))
        target["data"] = blob
        assert spliced == encode(body)


def test_record_cli_limits_and_output(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("stereocam.tools.recording.record.progress_wanted", lambda: True)  # as on a terminal
    assert cli.main(["record", "sim://?seed=2", "--out", str(tmp_path / "a.mcap"), "--frames", "0"]) == 2
    assert cli.main(["record", "sim://?seed=2", "--out", str(tmp_path / "a.mcap"), "--frames", "2", "--set",
                     "width=320", "--set", "height=240"]) == 0
    captured = capsys.readouterr()
    assert "2 frames" in captured.out and "recorder 0" in captured.out
    assert "fps" in captured.err and "MB/s" in captured.err  # the progress line
