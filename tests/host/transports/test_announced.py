"""Served simulators announce themselves in a per-user runtime file; stale files are ignored and removed."""
from __future__ import annotations

import json
import logging
import subprocess
import sys

import pytest

from stereocam.protocol import messages as m
from stereocam.protocol.framing import Decoder
from stereocam.transports import announced


@pytest.fixture
def runtime(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    return tmp_path / "stereocam"


def test_announcement_lives_as_long_as_the_block(runtime):
    with announced.announce("socket://127.0.0.1:9", "SN-1", "STOC-SIM", "1.1.0", "tcp") as path:
        assert path.parent == runtime and (runtime.stat().st_mode & 0o777) == 0o700
        [entry] = announced.discover()
        assert (entry.url, entry.serial, entry.transport, entry.simulated) == ("socket://127.0.0.1:9", "SN-1", "tcp",
                                                                               True)
    assert announced.discover() == [] and not path.exists()


def test_a_dead_process_announcement_is_ignored_and_removed(runtime):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    runtime.mkdir(mode=0o700)
    stale = runtime / f"served-{dead.stdout.strip()}.json"
    stale.write_text(json.dumps({"url": "/dev/pts/999", "serial": "GONE", "pid": int(dead.stdout)}))
    (runtime / "served-junk.json").write_text("{half a file")
    assert announced.discover() == []
    assert not stale.exists()


def test_payload_crc_errors_are_logged_with_context(caplog):
    packet = bytearray(m.encode(m.GetConfig(), 77))
    packet[-1] ^= 0xFF
    with caplog.at_level(logging.INFO, logger="stereocam.protocol.framing"):
        assert Decoder().feed(bytes(packet)) == []
    assert any("CRC" in r.getMessage() and "request id 77" in r.getMessage() for r in caplog.records)
