"""Recordings that are damaged, cut short or hostile, and clumsy arguments to the recording tools:
typed errors naming the file and the field, clean exits, and never a byte of good data lost."""
from __future__ import annotations

import os
import pickle
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

import stereocam
from stereocam.recording import Recorder, RecordingError, describe
from stereocam.recording.reader import DamagedRecordingError, Recording
from stereocam.recording.recorder import FRAME_INDEX
from stereocam.recording.repair import repair
from stereocam.tools import cli
from stereocam.tools.soak.recordings import BOMBS, bomb, with_chunk_replaced
from tests.support.hangs import returns_within

N = 5


@pytest.fixture(scope="module")
def ok(tmp_path_factory) -> Path:
    """The audit's recording: 5 frames of sim://?seed=1 at the default size, two chunks."""
    path = tmp_path_factory.mktemp("ok") / "ok.mcap"
    assert cli.main(["record", "sim://?seed=1", "--frames", str(N), "--out", str(path), "--quiet"]) == 0
    return path


def _chunks(path: Path) -> list:
    with open(path, "rb") as f:
        return sorted(make_reader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)


def _sequences(path: Path) -> list[int]:
    with Recording(path) as rec:
        return [c.info.sequence for c in rec.captures()]


def _run(argv: list[str], capsys) -> tuple[int, str]:
    """``stereocam ARGV`` in this process: exit code and stderr (with no traceback in it)."""
    rc = cli.main(argv)
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return rc, err


# -- 1. repair keeps every good chunk, and the original -------------------------------------------
def _flip(src: Path, dst: Path, offset: int, n: int = 16) -> bytes:
    data = bytearray(src.read_bytes())
    for i in range(offset, offset + n):
        data[i] ^= 0xFF
    dst.write_bytes(bytes(data))
    return bytes(data)


def test_repair_in_place_skips_a_damaged_chunk_and_keeps_the_rest_and_the_original(ok, tmp_path, capsys):
    first = _chunks(ok)[0]
    bad = tmp_path / "bad.mcap"
    damaged = _flip(ok, bad, first.chunk_start_offset + first.chunk_length // 2)
    readable = []  # frames the damaged file still gives, read one by one through its own index
    with Recording(bad) as rec:
        for i in range(len(rec)):
            try:
                readable.append(rec.capture(i).info.sequence)
            except DamagedRecordingError:
                pass
    assert 0 < len(readable) < N
    rc = cli.main(["recording", "repair", str(bad)])
    out = capsys.readouterr().out
    assert rc == 0
    assert f"{len(readable)} frames kept, 1 chunks damaged and skipped" in out and "cut short" not in out
    kept = tmp_path / "bad.mcap.damaged"
    assert f"the original is kept as {kept}" in out and kept.read_bytes() == damaged
    assert _sequences(bad) == readable
    with Recording(ok) as a, Recording(bad) as b:  # the kept frames are the recorded ones, bit for bit
        by_seq = {c.info.sequence: c for c in a.captures()}
        for c in b.captures():
            assert np.array_equal(c.disparity, by_seq[c.info.sequence].disparity)
            assert np.array_equal(c.left, by_seq[c.info.sequence].left)
        assert b.metadata["stereocam.summary"]["frames"] == str(len(readable))


def test_a_record_length_that_cannot_be_trusted_ends_the_scan_and_says_so(ok, tmp_path):
    second = _chunks(ok)[1]
    bad = tmp_path / "len.mcap"
    _flip(ok, bad, second.chunk_start_offset + 1, 8)  # the chunk record's length: ~2^64
    r = repair(bad, tmp_path / "out.mcap")
    assert r.stopped_at == second.chunk_start_offset and r.unreadable_bytes == bad.stat().st_size - r.stopped_at
    assert not r.cut_short and "could not be read" in r.line() and "cut short" not in r.line()
    assert r.original is None and bad.read_bytes()[:16] == ok.read_bytes()[:16]  # --out: the input untouched
    assert r.frames >= 1 and _sequences(tmp_path / "out.mcap") == _sequences(ok)[:r.frames]


def test_repair_of_a_file_cut_short_says_so_and_keeps_the_original(ok, tmp_path):
    cut = tmp_path / "cut.mcap"
    data = ok.read_bytes()[:_chunks(ok)[1].chunk_start_offset + 1000]
    cut.write_bytes(data)
    r = repair(cut)
    assert r.cut_short and "cut short" in r.line() and r.damaged_chunks == 0 and r.frames >= 1
    assert r.original == tmp_path / "cut.mcap.damaged" and r.original.read_bytes() == data
    assert repair(cut).original == tmp_path / "cut.mcap.damaged.1"  # a second repair replaces no kept file


def test_repair_never_writes_over_another_file(ok, tmp_path, capsys):
    other = tmp_path / "other.mcap"
    other.write_bytes(b"precious")
    rc, err = _run(["recording", "repair", str(ok), "--out", str(other)], capsys)
    assert rc == 1 and "already exists" in err and other.read_bytes() == b"precious"


# -- 2. a recording never replaces a file; the zstd level is checked first ------------------------
def test_record_cli_refuses_an_existing_file_and_a_bad_level(ok, tmp_path, capsys):
    keep = tmp_path / "keep.mcap"
    keep.write_bytes(ok.read_bytes())
    rc, err = _run(["record", "sim://?seed=1", "--level", "99", "--frames", "3", "--out", str(keep), "--quiet"],
                   capsys)
    assert rc == 2 and "--level" in err
    assert keep.read_bytes() == ok.read_bytes() and _sequences(keep) == _sequences(ok)
    rc, err = _run(["record", "sim://?seed=1", "--frames", "3", "--out", str(keep), "--quiet"], capsys)
    assert rc == 2 and "already exists" in err and keep.read_bytes() == ok.read_bytes()
    rc, err = _run(["record", "sim://?seed=1", "--level", "23", "--frames", "1", "--out", str(tmp_path / "n.mcap"),
                    "--quiet"], capsys)
    assert rc == 2 and not (tmp_path / "n.mcap").exists()


def test_camera_record_and_recorder_refuse_an_existing_file_and_a_bad_level(tmp_path):
    keep = tmp_path / "keep.mcap"
    keep.write_bytes(b"earlier recording")
    with stereocam.open("sim://?seed=1", timeout=3.0) as cam:
        with pytest.raises(RecordingError, match="already exists"):
            cam.record(keep, frames=1)
        for level in (23, 1.5, "3", True):
            with pytest.raises(stereocam.ConfigError, match="zstd level"):
                cam.record(tmp_path / "new.mcap", frames=1, level=level)
        unit = describe(cam)
    with pytest.raises(RecordingError, match="already exists"):
        Recorder(keep, unit)
    with pytest.raises(stereocam.ConfigError):
        Recorder(tmp_path / "new.mcap", unit, level=99)
    assert keep.read_bytes() == b"earlier recording" and sorted(p.name for p in tmp_path.iterdir()) == ["keep.mcap"]


# -- 3. damaged metadata and indexes: typed errors naming the file and the field ------------------
def _rewrite(src: Path, dst: Path, metadata: Callable[[dict], dict] = lambda m: m,
             index: Callable[[np.ndarray], np.ndarray] = lambda t: t, messages: bool = True,
             capture: Callable[[str, bytes], bytes] = lambda topic, data: data,
             schema: Callable[[bytes], bytes] = lambda data: data) -> Path:
    """``src`` written again by the mcap library's own Writer, its metadata, frame index, messages
    (``capture(topic, data)``) and schema texts changed."""
    with open(src, "rb") as f, open(dst, "wb") as out:
        reader = make_reader(f)
        summary = reader.get_summary()
        w = Writer(out, compression=CompressionType.ZSTD)
        w.start(profile="ros2", library="test")
        schema_ids = {sid: w.register_schema(s.name, s.encoding, schema(s.data)) for sid, s in summary.schemas.items()}
        channel_ids = {cid: w.register_channel(c.topic, c.message_encoding, schema_ids[c.schema_id], c.metadata)
                       for cid, c in summary.channels.items()}
        if messages:
            for _, channel, m in reader.iter_messages():
                w.add_message(channel_ids[channel.id], m.log_time, capture(channel.topic, m.data), m.publish_time,
                              m.sequence)
        meta = metadata({m.name: dict(m.metadata) for m in reader.iter_metadata()})
        for name, data in meta.items():
            w.add_metadata(name, data)
        for a in reader.iter_attachments():
            data = index(np.frombuffer(a.data, "<i8")).astype("<i8").tobytes() if a.name == FRAME_INDEX else a.data
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, data)
        w.finish()
    return dst


def _set(record: str, key: str, value: str) -> Callable[[dict], dict]:
    return lambda m: {**m, record: {**m[record], key: value}}


INFO = (["recording", "info"], ["recording", "info", "--json"])
REPLAY = (["info", "replay://"],)  # the file is appended
REMATCH = (["rematch", "--workers", "1", "--out"],)  # the output folder, then the file, are appended
# field -> (how it is damaged, the commands that need it and must fail naming it)
DAMAGED_METADATA = {
    "body_hex": (_set("stereocam.calibration", "body_hex", "zz"), INFO + REPLAY + REMATCH),
    "generation": (_set("stereocam.calibration", "generation", "x"), INFO + REPLAY + REMATCH),
    "calibration_id": (_set("stereocam.calibration", "calibration_id", ""), INFO + REPLAY + REMATCH),
    "width": (_set("stereocam.config", "width", "wide"), INFO + REPLAY + REMATCH),
    "link_lost": (_set("stereocam.summary", "link_lost", "many"), INFO),
    "clock_offset_ns": (_set("stereocam.recording", "clock_offset_ns", "soon"), REMATCH),
}


def _argv(command: list[str], bad: Path, tmp_path: Path) -> list[str]:
    if command[0] == "rematch":
        return [*command, str(tmp_path / "rm"), str(bad)]
    if command[-1] == "replay://":
        return [*command[:-1], f"replay://{bad}?speed=fast"]
    return [*command[:2], str(bad), *command[2:]]


@pytest.mark.parametrize("field", sorted(DAMAGED_METADATA))
def test_a_damaged_metadata_value_is_a_typed_error_naming_file_and_field(ok, tmp_path, capsys, field):
    damage, commands = DAMAGED_METADATA[field]
    bad = _rewrite(ok, tmp_path / "meta.mcap", damage)
    named = rf"meta\.mcap: metadata \S+ field '{field}'"
    with Recording(bad) as rec, pytest.raises(DamagedRecordingError, match=named):
        _ = rec.calibration, rec.config, rec.summary_counts, rec.clock_offset_ns, rec.unit
    for command in commands:
        rc, err = _run(_argv(command, bad, tmp_path), capsys)
        assert rc == 1 and f"'{field}'" in err and "meta.mcap" in err, command
    # what does not need the field still works: the frames export
    assert cli.main(["recording", "export", str(bad), "--out", str(tmp_path / "x"), "--stop", "2"]) == 0
    assert "2 frames exported" in capsys.readouterr().out


def test_a_recording_without_the_unit_identity_cannot_be_replayed_but_can_be_read(ok, tmp_path, capsys):
    bad = _rewrite(ok, tmp_path / "anon.mcap", lambda m: {k: v for k, v in m.items() if k != "stereocam.device"})
    assert _sequences(bad) == _sequences(ok)
    assert cli.main(["recording", "info", str(bad)]) == 0 and "frames    5" in capsys.readouterr().out
    rc, err = _run(["info", f"replay://{bad}?speed=fast"], capsys)
    assert rc == 1 and "anon.mcap" in err and "model" in err


def test_frame_index_times_that_match_no_messages_are_damage_not_silence(ok, tmp_path, capsys):
    bad = _rewrite(ok, tmp_path / "index.mcap", index=lambda t: t + 1)
    with Recording(bad) as rec:
        assert len(rec) == N
        with pytest.raises(DamagedRecordingError, match=r"index\.mcap: frame 0 cannot be read") as caught:
            rec.capture(0)
        assert caught.value.frame == 0
        with pytest.raises(DamagedRecordingError, match="frame 3"):
            rec.capture(3)
        with pytest.raises(DamagedRecordingError):
            list(rec.captures())
    rc, err = _run(["recording", "export", str(bad), "--out", str(tmp_path / "x")], capsys)
    assert rc == 1 and "cannot be read" in err and "0 frames exported" not in capsys.readouterr().out
    rc, err = _run(["info", f"replay://{bad}"], capsys)
    assert rc == 1 and "frame 0 cannot be read" in err


def test_a_frame_index_with_no_messages_behind_it_is_damage(ok, tmp_path, capsys):
    bad = _rewrite(ok, tmp_path / "empty.mcap", messages=False)
    with pytest.raises(DamagedRecordingError, match=r"empty\.mcap: its frame index lists 5 frames"):
        Recording(bad)
    for argv in (["recording", "export", str(bad), "--out", str(tmp_path / "x")], ["recording", "info", str(bad)],
                 ["info", f"replay://{bad}"]):
        rc, err = _run(argv, capsys)
        assert rc == 1 and "frame index lists 5 frames" in err, argv


def test_a_damaged_recording_error_survives_pickling_with_its_frame():
    """Dask hands a worker's error to the client pickled: it must arrive whole."""
    err = pickle.loads(pickle.dumps(DamagedRecordingError("x.mcap: frame 3 cannot be read", 3)))
    assert isinstance(err, DamagedRecordingError) and err.frame == 3 and str(err) == "x.mcap: frame 3 cannot be read"


# -- 4. export ranges ------------------------------------------------------------------------------
@pytest.mark.parametrize("args", [["--start", "-9"], ["--start", "-2"], ["--stop", "-1"]])
def test_export_refuses_negative_frame_numbers(ok, tmp_path, capsys, args):
    rc, err = _run(["recording", "export", str(ok), "--out", str(tmp_path / "x"), *args], capsys)
    assert rc == 2 and "not negative" in err and not (tmp_path / "x").exists()
    with Recording(ok) as rec, pytest.raises(stereocam.ConfigError):
        rec.captures(-2)


# -- 5. cut short: the error names the repair -----------------------------------------------------
@pytest.mark.parametrize("keep", [8, 9, 5000, 1_000_000, -50])
def test_a_file_cut_short_names_the_repair_command(ok, tmp_path, capsys, keep):
    data = ok.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:keep])
    with pytest.raises(RecordingError, match=r"cut\.mcap is truncated or damaged.*stereocam recording repair"):
        Recording(cut)
    rc, err = _run(["recording", "info", str(cut)], capsys)
    assert rc == 1 and f"stereocam recording repair {cut}" in err


# -- 7. not a regular file --------------------------------------------------------------------------
def test_a_fifo_is_refused_not_waited_on(tmp_path, capsys):
    fifo = tmp_path / "x.mcap"
    os.mkfifo(fifo)
    with pytest.raises(RecordingError, match="not a regular file"):
        returns_within(20, lambda: Recording(fifo))
    with pytest.raises(RecordingError, match="not a regular file"):
        returns_within(20, lambda: repair(fifo))
    rc, err = returns_within(20, lambda: _run(["recording", "info", str(fifo)], capsys))
    assert rc == 1 and "not a regular file" in err
    with pytest.raises(RecordingError, match="not a regular file"):
        Recording(tmp_path)  # a folder


# -- issue 22 item 4: repair and rematch never destroy a file --------------------------------------
def test_repair_leaves_an_existing_repair_tmp_and_the_target_of_a_link_alone(ok, tmp_path, capsys):
    victim = tmp_path / "victim.txt"
    victim.write_bytes(b"victim")
    for name, kind in (("a.mcap", "file"), ("b.mcap", "link")):
        bad = tmp_path / name
        bad.write_bytes(ok.read_bytes()[:_chunks(ok)[1].chunk_start_offset + 1000])
        tmp = tmp_path / f"{name}.repair-tmp"
        if kind == "file":
            tmp.write_bytes(b"someone's file")
        else:
            tmp.symlink_to(victim)
        rc, _ = _run(["recording", "repair", str(bad)], capsys)
        assert rc == 0 and _sequences(bad)
        assert (tmp.read_bytes() if kind == "file" else os.readlink(tmp)) == (
            b"someone's file" if kind == "file" else str(victim))
    assert victim.read_bytes() == b"victim"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["a.mcap", "a.mcap.damaged", "a.mcap.repair-tmp", "b.mcap", "b.mcap.damaged", "b.mcap.repair-tmp",
         "victim.txt"])


def test_repair_creates_its_temporary_file_exclusively_never_through_a_link(ok, tmp_path, monkeypatch):
    import stereocam.recording.repair as repair_module

    class _Fixed:
        hex = "0" * 32

    monkeypatch.setattr(repair_module.uuid, "uuid4", lambda: _Fixed())
    victim = tmp_path / "victim.txt"
    victim.write_bytes(b"victim")
    (tmp_path / f".out.mcap.{'0' * 12}.repair-tmp").symlink_to(victim)
    with pytest.raises(FileExistsError):
        repair(ok, tmp_path / "out.mcap")
    assert victim.read_bytes() == b"victim" and not (tmp_path / "out.mcap").exists()
    assert os.path.islink(tmp_path / f".out.mcap.{'0' * 12}.repair-tmp")


# -- issue 22 item 3: compression bombs --------------------------------------------------------------
@pytest.mark.parametrize("name", BOMBS)
def test_a_compression_bomb_is_damage_read_in_bounded_time_and_memory(ok, tmp_path, capsys, name):
    import resource

    bad = with_chunk_replaced(ok, tmp_path / "bomb.mcap", *bomb(name))
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB
    rc, err = returns_within(20, _run, ["recording", "export", str(bad), "--out", str(tmp_path / "x")], capsys)
    assert rc == 1 and "bomb.mcap: frame" in err and "cannot be read" in err
    r = returns_within(20, repair, bad, tmp_path / "fixed.mcap")
    assert r.damaged_chunks == 1 and 0 < r.frames < N and _sequences(tmp_path / "fixed.mcap")
    grown_mib = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024
    assert grown_mib < 200, f"reading the bomb grew the process by {grown_mib:.0f} MiB"


# -- issue 22 item 7: hostile values in the messages are damage, never a traceback -------------------
def _capture_info(change: Callable[[dict], dict]) -> Callable[[str, bytes], bytes]:
    """A message transform: each CaptureInfo decoded, changed by ``change`` and encoded again."""
    from mcap_ros2.decoder import DecoderFactory
    from mcap.records import Schema

    from stereocam.recording import schemas

    name = schemas.CAPTURE_INFO
    decode = DecoderFactory().decoder_for("cdr", Schema(id=1, data=schemas.msgdef(name).encode(), encoding="ros2msg",
                                                             name=name))
    encode = schemas.encoder(name)

    def run(topic: str, data: bytes) -> bytes:
        if topic != schemas.CAPTURE:
            return data
        m = decode(data)
        body = {f: getattr(m, f) for f in schemas.CAPTURE_INFO_FIELDS if f != "header"}
        body["header"] = {"stamp": {"sec": m.header.stamp.sec, "nanosec": m.header.stamp.nanosec},
                          "frame_id": m.header.frame_id}
        return encode(change(body))
    return run


HOSTILE_VALUES = {
    "status outside the enumeration": dict(capture=_capture_info(lambda b: {**b, "status": "on fire"})),
    "a 65535x65535 frame": dict(capture=_capture_info(lambda b: {**b, "width": 65535, "height": 65535})),
    "a renamed schema field": dict(schema=lambda d: d.replace(b"uint32 sequence", b"uint32 sequense")),
}


@pytest.mark.parametrize("case", sorted(HOSTILE_VALUES))
def test_a_hostile_capture_value_is_a_damaged_recording_exit_1(ok, tmp_path, capsys, case):
    bad = _rewrite(ok, tmp_path / "hostile.mcap", **HOSTILE_VALUES[case])
    with Recording(bad) as rec, pytest.raises(DamagedRecordingError, match=r"hostile\.mcap: frame 0 cannot be read"):
        rec.capture(0).to_frame()
    for argv in (["recording", "export", str(bad), "--out", str(tmp_path / "x")],
                 ["rematch", "--workers", "1", "--out", str(tmp_path / "rm"), str(bad)]):
        rc, err = _run(argv, capsys)
        assert rc == 1 and "hostile.mcap: frame" in err and "cannot be read" in err, argv


@pytest.mark.parametrize("claim", [4 << 30, 1 << 40])
def test_a_zstd_header_claim_allocates_nothing_under_an_address_space_limit(claim):
    """The mechanism: decompression never sizes a buffer from the zstd header (the mcap library's
    one-shot decompress does: MemoryError under this limit); the claim is damage, said so."""
    import subprocess
    import sys

    code = ("import resource, sys\n"
            "resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))\n"
            "from mcap.records import Chunk\n"
            "from stereocam.recording.chunks import chunk_data\n"
            "from stereocam.tools.soak.recordings import claiming_zstd\n"
            f"c = Chunk(compression='zstd', data=claiming_zstd({claim}), message_end_time=0, message_start_time=0, "
            "uncompressed_crc=0, uncompressed_size=1000)\n"
            "try:\n"
            "    chunk_data(c, 12 << 20)\n"
            "except ValueError as exc:\n"
            "    print('refused:', exc)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.startswith("refused: a chunk"), r.stdout + r.stderr[-2000:]


# -- audit: an --out that cannot be written is named as given, not by the temporary file's name ------
def test_an_out_in_no_folder_is_named_as_given_before_the_input_is_read(tmp_path, capsys):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not read: the folder is checked first")
    out = tmp_path / "nodir" / "o.mcap"
    with pytest.raises(FileNotFoundError, match="no folder .*nodir' to write into") as refused:
        repair(bad, out)
    assert refused.value.filename == str(out)
    rc, err = _run(["recording", "repair", str(bad), "--out", "/proc/x/o.mcap"], capsys)
    assert rc == 2 and "no folder '/proc/x' to write into: '/proc/x/o.mcap'" in err and "repair-tmp" not in err
    assert not out.parent.exists()


def test_a_folder_that_refuses_the_output_is_named_by_the_path_given(tmp_path, capsys):
    header_only = tmp_path / "h.mcap"
    with open(header_only, "wb") as f:  # an MCAP header: the repair gets as far as creating its file
        writer = Writer(f)
        writer.start(profile="ros2", library="test")
        writer.finish()
    rc, err = _run(["recording", "repair", str(header_only), "--out", "/proc/o.mcap"], capsys)
    assert rc == 2 and "'/proc/o.mcap'" in err and "repair-tmp" not in err
