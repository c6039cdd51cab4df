"""The firmware's link layer on its own: refusals become NACKs in one place, a RESEND is answered
from the replay cache without running the handler again, and the firmware's layout stays small."""
from __future__ import annotations

import ast
import collections
import dataclasses

from stereocam.protocol import messages as m
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.framing import FLAG_RESEND, Decoder
from stereocam.device_sim.link_layer.dispatcher import Dispatcher
from stereocam.device_sim.link_layer.refusal import Refusal
from tests.support.paths import REPO

DEVICE_SIM = REPO / "device_sim"


def packet(msg: m.Message, rid: int, flags: int = 0):
    return Decoder().feed(m.encode(msg, rid, flags))[0]


def reply(wire: bytes) -> m.Message:
    return m.decode_packet(Decoder().feed(wire)[0])


def test_refusal_and_faults_become_nacks_and_resends_replay() -> None:
    counters: collections.Counter[str] = collections.Counter()
    d = Dispatcher(counters)
    calls = []

    def trigger(msg):
        calls.append(msg)
        raise Refusal(ErrorCode.BUSY, "queue full", 6)

    d.register({m.MsgType.TRIGGER: trigger, m.MsgType.STOP: lambda _: 1 / 0, m.MsgType.START: lambda _: m.Started()})
    first = d.answer(packet(m.Trigger(), 9))
    assert reply(first) == m.Nack(m.MsgType.TRIGGER, ErrorCode.BUSY, 6, "queue full")
    assert d.answer(packet(m.Trigger(), 9, FLAG_RESEND)) == first and len(calls) == 1  # replayed, not re-run
    d.answer(packet(m.Trigger(), 9))  # without RESEND it runs again
    assert len(calls) == 2 and counters["resends_replayed"] == 1
    assert reply(d.answer(packet(m.Stop(), 10))).code == ErrorCode.INTERNAL
    assert reply(d.answer(packet(m.GetInfo(), 11))).code == ErrorCode.UNKNOWN_TYPE
    bad = dataclasses.replace(packet(m.Start(), 12), payload=b"x")  # START with a payload it must not have
    assert reply(d.answer(bad)).code == ErrorCode.BAD_PAYLOAD
    assert reply(d.answer(packet(m.Start(), 13, FLAG_RESEND))) == m.Started()  # not cached: executed
    assert counters["nacks"] == 5


def test_firmware_modules_are_small_and_layered() -> None:
    files = [p for p in DEVICE_SIM.rglob("*.py") if "matching" not in p.parts]
    assert not [p for p in files if p.name == "camera.py"]  # one camera.py (the host's) only
    assert {p.name: n for p in files if (n := len(p.read_text().splitlines())) > 300} == {}
    for p in (DEVICE_SIM / "link_layer").glob("*.py"):  # the link layer knows no handler or pipeline
        imported = {n.module or "" for n in ast.walk(ast.parse(p.read_text())) if isinstance(n, ast.ImportFrom)}
        assert not [i for i in imported if "handlers" in i or "pipeline" in i or "rig" in i], p.name
