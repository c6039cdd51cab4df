"""The cases of the publishable golden vectors (SPEC §15): configuration acceptance and the decoder.

The expected answers are computed here by the reference rules (protocol/config_rules.py) and the
reference decoder (protocol/framing.py), reviewed, and frozen in protocol/golden/*.json; the tests
then hold the Python firmware and both reference implementations to the frozen files. Regenerate
only with a deliberate SPEC change, and review the diff:

    .venv/bin/python -m tests.protocol.golden_cases --regenerate
"""
from __future__ import annotations

import json
import struct
import sys
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from stereocam.protocol import messages as m
from stereocam.protocol.config_rules import ConfigRejected, merge
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.framing import MAGIC, VERSION_MAJOR, VERSION_MINOR, Decoder, header_crc
from stereocam.protocol.params import BY_NAME, INT32_MAX, INT32_MIN, PARAMS, defaults
from tests.support import paths

GOLDEN_DIR = paths.REPO / "protocol" / "golden"
CONFIG_FILE = GOLDEN_DIR / "config_acceptance.json"
DECODER_FILE = GOLDEN_DIR / "decoder.json"
ALL_CAPABILITIES = sum(v for k, v in vars(m.Capability).items() if k.isupper())  # every bit this version defines


@dataclass(frozen=True)
class Device:
    """What a configuration case assumes of the device: its INFO."""

    name: str
    capabilities: int
    max_width: int = 1280
    max_height: int = 960
    stage_limits: tuple[tuple[int, int, int], ...] = ()

    def limits(self) -> dict[int, tuple[int, int]]:
        return {s: (w, h) for s, w, h in self.stage_limits}


FULL = Device("full", ALL_CAPABILITIES)
MINIMAL = Device("minimal", m.Capability.DISPARITY | m.Capability.SOFTWARE_TRIGGER | m.Capability.TIME_SYNC)
SMALL_SGM = Device("sgm_up_to_vga", ALL_CAPABILITIES, stage_limits=((m.Stage.SEMI_GLOBAL, 640, 480),))


def _answer(device: Device, before: dict[str, int], entries: list[tuple[int, int]], streaming: bool) -> dict:
    try:
        after = merge(before, entries, streaming, device.capabilities, device.limits())
    except ConfigRejected as exc:
        return {"accept": False, "code": ErrorCode(exc.code).name, "param_id": exc.param_id}
    return {"accept": True, "changed": {k: v for k, v in after.items() if before[k] != v}}


def _ids(*pairs: tuple[str, int]) -> list[tuple[int, int]]:
    return [(BY_NAME[n].pid if n in BY_NAME else int(n), v) for n, v in pairs]


def config_requests() -> Iterator[tuple[str, Device, dict[str, int], bool, list[tuple[int, int]]]]:
    """(what, device, before, streaming, entries) for every case."""
    base = defaults()
    triggered = {**base, "trigger_mode": 1}
    for p in PARAMS:  # every parameter at and beyond its limits, alone
        probes = {p.lo, p.hi, p.lo - 1, p.hi + 1, INT32_MIN, INT32_MAX}
        if p.odd:
            probes.add(p.lo + 1)
        if p.step > 1:
            probes.add(p.lo + p.step // 2)
        for v in sorted(probes):
            yield f"{p.name}={v}", FULL, triggered, False, _ids((p.name, v))
    for (name, value) in (("trigger_mode", 2), ("rectify", 0), ("trigger_output", 1), ("algorithm", 1)):
        for device in (FULL, MINIMAL):  # SPEC §5.1 capability-bound values
            yield f"{name}={value} on {device.name}", device, triggered, False, _ids((name, value))
    yield "trigger_output=1 in external mode on full", FULL, triggered, False, _ids(("trigger_mode", 2),
                                                                                    ("trigger_output", 1))
    cross = [  # SPEC §5.2 rules, refused and a legal neighbour
        ("block_size", (("width", 64), ("height", 48), ("block_size", 49), ("pre_filter_size", 5))),
        ("block_size", (("width", 64), ("height", 48), ("block_size", 47), ("pre_filter_size", 5),
                        ("num_disparities", 16))),
        ("pre_filter_size", (("width", 64), ("height", 48), ("pre_filter_size", 49), ("block_size", 5))),
        ("num_disparities", (("width", 64), ("num_disparities", 64), ("block_size", 5))),
        ("min_disparity", (("width", 64), ("num_disparities", 16), ("min_disparity", -60), ("block_size", 5))),
        ("exposure_us", (("trigger_mode", 0), ("fps", 120), ("exposure_us", 8334))),
        ("exposure_us", (("trigger_mode", 0), ("fps", 120), ("exposure_us", 8333))),
        ("fps", (("trigger_mode", 0), ("exposure_us", 100_000), ("fps", 11))),
        ("algorithm", (("algorithm", 1), ("width", 64), ("num_disparities", 256))),
        ("trigger_output", (("trigger_output", 1), ("trigger_mode", 1))),
    ]
    for what, pairs in cross:
        yield f"cross rule on {what}: {dict(pairs)}", FULL, triggered, False, _ids(*pairs)
    yield "cross rule blames the listed parameter the request touched", FULL, {**base, "fps": 120}, False, \
        _ids(("exposure_us", 9000))
    yield "cross rule blames the first listed when the request touched none of its parameters", FULL, \
        {**base, "exposure_us": 9000, "trigger_mode": 1, "fps": 120}, False, _ids(("trigger_mode", 0))
    # SPEC §4.3: duplicates, unknown ids, order, streaming
    yield "duplicate id: the last value is used", FULL, base, False, _ids(("gain", 10), ("gain", 20))
    yield "duplicate id: an invalid earlier value refuses", FULL, base, False, _ids(("gain", 241), ("gain", 20))
    yield "duplicate id: an invalid later value refuses", FULL, base, False, _ids(("gain", 20), ("gain", -1))
    yield "first failure wins: range before unknown id", FULL, base, False, _ids(("fps", 0), ("20", 1))
    yield "first failure wins: unknown id first", FULL, base, False, _ids(("20", 1), ("fps", 0))
    yield "retired id 20", FULL, base, False, _ids(("20", 0))
    yield "id never assigned", FULL, base, False, _ids(("32766", 1))
    yield "empty request", FULL, base, False, []
    yield "streaming: non-live change", FULL, base, True, _ids(("width", 320))
    yield "streaming: non-live value as in force", FULL, base, True, _ids(("width", 640), ("gain", 5))
    yield "streaming: duplicate ending on the value in force", FULL, base, True, _ids(("width", 320),
                                                                                        ("width", 640))
    yield "streaming: live change", FULL, base, True, _ids(("gain", 5), ("fps", 10))
    yield "streaming: range before state", FULL, base, True, _ids(("width", 100))
    # SPEC §5.2 rule 8: INFO stage limits
    yield "SGM beyond its stage limit", SMALL_SGM, base, False, _ids(("algorithm", 1), ("width", 1280),
                                                                      ("height", 960))
    yield "SGM selected while the format exceeds its limit", SMALL_SGM, {**base, "width": 1280, "height": 960}, \
        False, _ids(("algorithm", 1))
    yield "SGM within its stage limit", SMALL_SGM, base, False, _ids(("algorithm", 1), ("width", 640),
                                                                      ("height", 480))
    yield "block matching has no stage limit here", SMALL_SGM, base, False, _ids(("width", 1280), ("height", 960))


def build_config_vectors() -> dict:
    cases = []
    for what, device, before, streaming, entries in config_requests():
        cases.append({"what": what, "device": {"capabilities": device.capabilities, "max_width": device.max_width,
                                               "max_height": device.max_height,
                                               "stage_limits": [list(s) for s in device.stage_limits]},
                      "before": before, "streaming": streaming, "request": [list(e) for e in entries],
                      "expect": _answer(device, before, entries, streaming)})
    return {"_comment": "SPEC §15: SET_CONFIG requests (ordered [param_id, value] entries, duplicates included) "
                        "on a device in state 'before' and the answer SPEC §4.3, §5.1 and §5.2 demand. "
                        "'changed' lists the parameters whose value the accepted request changed.",
            "protocol_version": [VERSION_MAJOR, VERSION_MINOR], "cases": cases}


# -- decoder ----------------------------------------------------------------------------------------
def _frame(msg_type: int, rid: int, payload: bytes = b"", *, major: int = 1, header_len: int = 20,
           payload_len: int | None = None, ext: bytes = b"") -> bytes:
    n = len(payload) if payload_len is None else payload_len
    head = struct.pack("<4sBBBBHHIH", MAGIC, major, VERSION_MINOR, header_len, 0, msg_type, rid, n, 0)
    return head + struct.pack("<H", header_crc(head)) + ext + payload + struct.pack("<I", zlib.crc32(ext + payload))


def _stray(n: int = 1024) -> bytes:
    """A CRC-valid header announcing ``n`` payload bytes that never come."""
    return _frame(m.MsgType.SET_CONFIG, 0x5555, payload_len=n)[:20]


GET_INFO = _frame(m.MsgType.GET_INFO, 1)
SET_GAIN = _frame(m.MsgType.SET_CONFIG, 2, m.SetConfig({5: 120}).pack())


def decoder_streams() -> Iterator[tuple[str, int, float, list[tuple[float, bytes]]]]:
    """(what, max_payload, T, [(arrival time, bytes)]) per case; empty bytes = a poll."""
    full = 1 << 20
    yield "one frame", full, 1.0, [(0.0, GET_INFO)]
    yield "two frames in one chunk", full, 1.0, [(0.0, GET_INFO + SET_GAIN)]
    yield "a frame a byte at a time", full, 1.0, [(i * 0.001, SET_GAIN[i:i + 1]) for i in range(len(SET_GAIN))]
    yield "garbage, then a frame", full, 1.0, [(0.0, b"\x00\xffSTO garbage" + GET_INFO)]
    yield "a partial magic at the end is kept", full, 1.0, [(0.0, b"xxSTO"), (0.1, b"C" + GET_INFO[4:])]
    bad_head = bytearray(GET_INFO)
    bad_head[10] ^= 1
    yield "bad header CRC, then a frame", full, 1.0, [(0.0, bytes(bad_head) + SET_GAIN)]
    bad_payload = bytearray(SET_GAIN)
    bad_payload[-1] ^= 0xFF
    yield "bad payload CRC, then a frame", full, 1.0, [(0.0, bytes(bad_payload) + GET_INFO)]
    yield "header_len 19 and 65", full, 1.0, [(0.0, _frame(1, 3, header_len=19) + _frame(1, 4, header_len=65)
                                                + bytes(45) + GET_INFO)]
    yield "header extension of 8 bytes", full, 1.0, [(0.0, _frame(1, 5, header_len=28, ext=bytes(range(8))))]
    yield "another major", full, 1.0, [(0.0, _frame(1, 6, major=2) + GET_INFO)]
    yield "oversize against max_payload 64", 64, 1.0, [(0.0, _frame(3, 7, bytes(65)) + GET_INFO)]
    yield "a false magic inside a payload", full, 1.0, [(0.0, _frame(0x4002, 0, b"\x00STOC" + bytes(30)))]
    yield "a stray header: the frame behind it waits for T", full, 1.0, [(0.0, _stray() + GET_INFO), (0.9, b"")]
    yield "a stray header: abandoned after T", full, 1.0, [(0.0, _stray() + GET_INFO), (1.01, b"")]
    yield "eight stray headers cost T in all (timed by arrival)", full, 1.0, \
        [(0.0, b"".join(_stray() for _ in range(8)) + GET_INFO), (1.01, b"")]
    yield "a stray header's wait runs from its own last byte", full, 1.0, \
        [(0.0, _stray()[:10]), (0.5, _stray()[10:] + GET_INFO), (1.2, b""), (1.51, b"")]
    yield "a frame completed in time is delivered", full, 1.0, [(0.0, SET_GAIN[:25]), (0.99, SET_GAIN[25:])]


def _packet(p: object) -> dict:
    return {"type": p.msg_type, "request_id": p.request_id, "flags": p.flags,  # type: ignore[attr-defined]
            "payload": p.payload.hex(), "version": list(p.version)}  # type: ignore[attr-defined]


def replay(max_payload: int, timeout: float, steps: list[tuple[float, bytes]]) -> tuple[list[dict], dict]:
    """Feed ``steps`` to a reference decoder; (delivered frames, counters)."""
    dec = Decoder(max_payload=max_payload, message_timeout=timeout)
    out = []
    for t, data in steps:
        out += [_packet(p) for p in dec.feed(data, t)]
    return out, dec.stats.as_dict()


def build_decoder_vectors() -> dict:
    cases = []
    for what, max_payload, timeout, steps in decoder_streams():
        frames, counters = replay(max_payload, timeout, steps)
        cases.append({"what": what, "max_payload": max_payload, "message_timeout_s": timeout,
                      "chunks": [{"t": t, "hex": data.hex()} for t, data in steps],
                      "frames": frames, "counters": counters})
    return {"_comment": "SPEC §3 and §15: byte streams fed chunk by chunk, each at its arrival time t (s; an empty "
                        "chunk is a poll at t), to a decoder with this max_payload and message timeout; the frames "
                        "it must deliver, in order, and its counters after the last chunk.",
            "protocol_version": [VERSION_MAJOR, VERSION_MINOR], "cases": cases}


def write(path: Path, doc: dict) -> None:
    """One case per line: a change shows as the cases it changes."""
    head = {k: v for k, v in doc.items() if k != "cases"}
    lines = [f" {json.dumps(k)}: {json.dumps(v, ensure_ascii=False)}," for k, v in head.items()]
    cases = ",\n".join(f"  {json.dumps(c, ensure_ascii=False)}" for c in doc["cases"])
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("{\n" + "\n".join(lines) + '\n "cases": [\n' + cases + "\n ]\n}\n", encoding="utf-8")
    print(f"wrote {path}")


if __name__ == "__main__":
    if sys.argv[1:] != ["--regenerate"]:
        sys.exit("usage: python -m tests.protocol.golden_cases --regenerate")
    write(CONFIG_FILE, build_config_vectors())
    write(DECODER_FILE, build_decoder_vectors())
