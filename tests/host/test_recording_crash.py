"""A recorder process killed with SIGKILL at random moments: the file reads up to its last complete
chunk as it is, and ``stereocam recording repair`` makes it whole (summary, indexes, every capture)."""
from __future__ import annotations

import random
import signal
import subprocess
import sys
import time

import pytest
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader

from stereocam.recording import schemas
from stereocam.recording.reader import Recording
from stereocam.tools import cli


def _record_then_kill(path, rng: random.Random) -> None:
    proc = subprocess.Popen([sys.executable, "-m", "stereocam.tools.cli", "record", "sim://?seed=5", "--out", str(path),
                             "--seconds", "120", "--set", "width=320", "--set", "height=240", "--set",
                             "num_disparities=32", "--quiet"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        target = rng.randint(300_000, 3_000_000)  # a random point in the stream of chunks
        deadline = time.monotonic() + 90
        while not (path.exists() and path.stat().st_size >= target):
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline, "recorder wrote too little"
            time.sleep(rng.uniform(0.001, 0.05))
        time.sleep(rng.uniform(0, 0.2))
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()


def _messages_as_is(path) -> int:
    n = 0
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f, emit_chunks=False, validate_crcs=True).records:
                n += type(record).__name__ == "Message"
        except (McapError, EOFError, ValueError):
            pass
    return n


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_sigkill_then_repair(tmp_path, seed):
    path = tmp_path / "killed.mcap"
    _record_then_kill(path, random.Random(seed))
    readable = _messages_as_is(path)
    assert readable > 0  # complete chunks read as they are, before any repair
    assert cli.main(["recording", "repair", str(path)]) == 0
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
        assert len(set(counts.values())) == 1 and counts.keys() == set(schemas.TOPICS)  # whole captures only
        assert sum(1 for _ in reader.iter_messages()) == summary.statistics.message_count <= readable
    with Recording(path) as rec:
        seqs = [c.info.sequence for c in rec.captures()]
        assert len(seqs) == counts[schemas.CAPTURE] > 0 and seqs == sorted(set(seqs))
        assert all(c.disparity is not None for c in rec.captures(len(rec) - 1))
        assert rec.metadata["stereocam.summary"]["repaired"] == "true"
