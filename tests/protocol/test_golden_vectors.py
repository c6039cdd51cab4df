"""The publishable golden vectors (SPEC §15, protocol/golden/): the Python firmware's configuration
store and receive path answer every case as the frozen files say, and the files still say what the
reference rules and decoder compute (a change there is a protocol change: see golden_cases.py)."""
from __future__ import annotations

import json
from importlib import resources

import pytest

from stereocam.device_sim.handlers.config_store import ConfigStore
from stereocam.device_sim.link_layer.refusal import Refusal
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.framing import VERSION_MAJOR, VERSION_MINOR, Decoder
from tests.protocol import golden_cases

CONFIG = json.loads(golden_cases.CONFIG_FILE.read_text(encoding="utf-8"))
DECODER = json.loads(golden_cases.DECODER_FILE.read_text(encoding="utf-8"))


def test_the_files_are_what_the_reference_computes() -> None:
    assert CONFIG == golden_cases.build_config_vectors()
    assert DECODER == golden_cases.build_decoder_vectors()
    assert CONFIG["protocol_version"] == DECODER["protocol_version"] == [VERSION_MAJOR, VERSION_MINOR]


def test_the_files_ship_in_the_package() -> None:
    shipped = resources.files("stereocam.protocol") / "golden"
    for name in ("config_acceptance.json", "decoder.json"):
        assert json.loads((shipped / name).read_text(encoding="utf-8"))["cases"]


def test_the_cases_cover_every_outcome() -> None:
    outcomes = {(c["expect"]["accept"], c["expect"].get("code")) for c in CONFIG["cases"]}
    assert outcomes == {(True, None), (False, "OUT_OF_RANGE"), (False, "UNKNOWN_PARAM"), (False, "BAD_STATE")}
    assert any(len({pid for pid, _ in c["request"]}) < len(c["request"]) for c in CONFIG["cases"])  # duplicates
    assert any(c["device"]["stage_limits"] for c in CONFIG["cases"])
    counters = {k for c in DECODER["cases"] for k, v in c["counters"].items() if v}
    assert counters == set(Decoder().stats.as_dict())


@pytest.mark.parametrize("case", CONFIG["cases"], ids=lambda c: c["what"])
def test_the_firmware_config_store_answers_each_case(case: dict) -> None:
    dev = case["device"]
    store = ConfigStore()
    store.reset(case["before"], dev["capabilities"], {s: (w, h) for s, w, h in dev["stage_limits"]})
    want = case["expect"]
    try:
        store.apply([tuple(e) for e in case["request"]], case["streaming"])
    except Refusal as refusal:
        assert not want["accept"], f"refused {ErrorCode(refusal.code).name} param {refusal.param_id}: {refusal}"
        assert (ErrorCode(refusal.code).name, refusal.param_id) == (want["code"], want["param_id"])
        assert store.snapshot() == case["before"]
        return
    assert want["accept"], f"accepted, expected {want['code']} naming {want['param_id']}"
    after = store.snapshot()
    assert {k: v for k, v in after.items() if case["before"][k] != v} == want["changed"]


@pytest.mark.parametrize("case", DECODER["cases"], ids=lambda c: c["what"])
def test_the_receive_path_decodes_each_stream(case: dict) -> None:
    dec = Decoder(max_payload=case["max_payload"], message_timeout=case["message_timeout_s"])
    frames = []
    for chunk in case["chunks"]:
        for p in dec.feed(bytes.fromhex(chunk["hex"]), chunk["t"]):
            frames.append({"type": p.msg_type, "request_id": p.request_id, "flags": p.flags,
                           "payload": p.payload.hex(), "version": list(p.version)})
    assert frames == case["frames"]
    assert dec.stats.as_dict() == case["counters"]
