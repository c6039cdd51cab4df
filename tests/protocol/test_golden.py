"""Golden wire vectors of protocol v1 (currently v1.3): the exact bytes every message class puts on the wire.

``tests/golden/protocol_v1.json`` pins, for one representative instance of EVERY class in
``protocol.messages.MESSAGES``, the complete frame (header + payload + CRC-32 trailer) as hex.
A failure here means the bytes on the wire changed: old devices and hosts will no longer
understand this code. That is almost always a bug, not a reason to update the file.

Regenerate the file ONLY for a deliberate, versioned protocol change (and bump the protocol
version / SPEC.md with it):

    .venv/bin/python -m tests.protocol.test_golden --regenerate

then review the diff of tests/golden/protocol_v1.json byte by byte.

History: v1.1 rewrote every vector (header byte 5, ver_minor, 0 -> 1; INFO gained its trailing
calibration_id) and added the eight CALIB_* messages of SPEC §12. Retiring parameter id 20 (a
simulator control, SPEC §5.1) shortened the CONFIG vector (every parameter of the table) by one entry.
v1.2 rewrote every vector again (ver_minor 1 -> 2) and added the four frame-repair messages of SPEC §13
and the twelve UPDATE_* messages of SPEC §14. v1.3 rewrote every vector again (ver_minor 2 -> 3); INFO
gained its trailing stage limits (SPEC §4.1).
"""
from __future__ import annotations

import binascii
import dataclasses
import enum
import json
import struct
import sys
import zlib

import pytest

from stereocam.protocol import messages as m
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.framing import (FLAG_RESEND, HEADER_LEN, MAGIC, TRAILER_LEN, VERSION_MAJOR, VERSION_MINOR,
                                        Decoder, Packet)
from stereocam.protocol.params import PARAMS
from tests.support import paths

GOLDEN = paths.GOLDEN / "protocol_v1.json"
SPEC = paths.REPO / "protocol" / "SPEC.md"
VERSION = (1, 3)  # the version these vectors pin; a change here is a protocol change

_COUNTERS = {name: (i + 1) * 1_000_003 for i, name in enumerate(m.COUNTERS)}
_COUNTERS["rx_bytes"] = (1 << 64) - 1  # full u64 range
_COUNTERS["nacks"] = 0

# (instance, request_id, flags), one per message class, with non-trivial field values.
CASES: list[tuple[m.Message, int, int]] = [
    (m.GetInfo(), 1, 0),
    (m.GetConfig(), 2, 0),
    (m.SetConfig({1: 1280, 8: 128, 10: -64, 18: -1, 14: 1 << 20}), 0x1234, FLAG_RESEND),
    (m.Trigger(), 0xFFFF, 0),
    (m.Start(), 0x0100, 0),
    (m.Stop(), 0x00FF, 0),
    (m.Heartbeat(), 0xBEEF, 0),
    (m.TimeSync(), 0x7FFF, 0),
    (m.Info(model="STOC-Σ1 stereo", serial="SN-00042-ß", firmware_version="1.2.3+çà", protocol_version=(1, 1),
            capabilities=0xA5A50F0F, sensor_width=1280, sensor_height=960, max_payload=1 << 20,
            max_width=1280, max_height=960, calibration_id=0x8BADF00D,
            stage_limits=((m.Stage.BLOCK_MATCHING, 1280, 960), (m.Stage.SEMI_GLOBAL, 640, 480))), 1, 0),
    (m.Config({p.pid: int(p.default) for p in PARAMS if p.pid <= 21}), 2, 0),  # the 1.1 table
    (m.ConfigApplied({1: 640, 10: -256, 14: 1 << 20, 0xFFFF: -(1 << 31), 0x1234: (1 << 31) - 1}), 0x1234, 0),
    (m.Triggered(trigger_id=0xDEADBEEF, sequence=42), 0xFFFF, 0),
    (m.Started(), 0x0100, 0),
    (m.Stopped(), 0x00FF, 0),
    (m.Status(uptime_us=0x0123456789ABCDEF, streaming=True, trigger_mode=1, counters=_COUNTERS), 0xBEEF, 0),
    (m.Time(device_time_us=1_700_000_000_123_456), 0x7FFF, 0),
    (m.Nack(request_type=m.MsgType.SET_CONFIG, code=int(ErrorCode.OUT_OF_RANGE), param_id=8,
            message="num_disparities=100: muss ein Vielfaches von 16 sein — 視差 ✗ 📷"), 0x1234, 0),
    (m.FrameBegin(sequence=0x01020304, trigger_id=7, device_time_us=123_456_789_012, exposure_us=4000, gain=120,
                  width=640, height=480, planes=7, flags=m.FRAME_RECTIFIED, disparity_format=m.DISPARITY_S16_Q4,
                  subpixel=16, min_disparity=-32, num_disparities=128, invalid_disparity=-32768,
                  calibration_id=0xC0FFEE, focal_px=812.5, cx=319.75, cy=-239.25, baseline_m=0.0625), 0, 0),
    (m.FrameData(sequence=0x01020304, plane=4, offset=0x00012340, data=bytes(range(0, 256, 7)) + MAGIC + b"\x00\xff"),
     0, 0),
    (m.FrameEnd(sequence=0x01020304, status=m.FRAME_SENSOR_OVERRUN, left_bytes=307200, right_bytes=307200,
                disparity_bytes=614400), 0, 0),
    # v1.1: calibration storage (SPEC §12)
    (m.CalibRead(source=m.CalibSource.FACTORY, offset=0x00010203, length=m.MAX_CALIB_CHUNK), 0x0203, FLAG_RESEND),
    (m.CalibData(source=m.CalibSource.USER, generation=0x01020304, calibration_id=0xCAFEBABE, total=248, offset=200,
                 data=bytes(range(255, 215, -1)) + MAGIC + b"\x00\xff\x80\x7f"), 0x0203, 0),
    (m.CalibWrite(offset=0x0000F000, total=0x00012345, data=b"\x01\x00\x05\x00" + MAGIC + bytes(range(24))),
     0xA00A, 0),
    (m.CalibWritten(staged=0x0000F01C), 0xA00A, 0),
    (m.CalibCommit(target=m.CalibSource.USER, total=248, crc=0xDEADBEEF), 0x0B0B, 0),
    (m.CalibRestore(), 0xFFFE, 0),
    (m.CalibCommitted(source=m.CalibSource.USER, generation=0x00C0FFEE, calibration_id=0x12345678), 0x0B0B, 0),
    (m.CalibRestored(source=m.CalibSource.FACTORY, generation=0xFFFFFFFF, calibration_id=1), 0xFFFE, 0),
    # v1.2: frame repair (SPEC §13)
    (m.SetFrameLink(chunk_size=1024), 0x0D0D, 0),
    (m.FrameLink(chunk_size=1024, kept_captures=8), 0x0D0D, 0),
    (m.FrameResend(sequence=0x01020304, ranges=((1, 0x400, 0x400), (4, 0x00012340, 0x0001FFFF))), 0x0E0E, FLAG_RESEND),
    (m.FrameResent(sequence=0x01020304, result=m.RESEND_SENT, frame_status=m.FRAME_OK, chunks=0x00000021), 0x0E0E, 0),
    # v1.2: firmware update (SPEC §14)
    (m.UpdateBegin(size=0x00200123, sha256=bytes(range(32)), flags=m.BEGIN_REPLACE), 0x0D0D, 0),
    (m.UpdateBegun(slot=1, received=0x0001F000, size=0x00200123), 0x0D0D, 0),
    (m.UpdateData(offset=0x0001F000, data=b"SCFW" + MAGIC + bytes(range(250, 256)) + b"\x00"), 0x0E0E, FLAG_RESEND),
    (m.UpdateWritten(slot=0, received=0x0001F00F, size=0x00200123), 0x0E0E, 0),
    (m.UpdateVerify(), 0x0F0F, 0),
    (m.UpdateVerified(m.SlotInfo(slot=1, state=m.SlotState.STANDBY, security_counter=0x01020000,
                                 sha256=bytes(range(255, 223, -1)), version="1.2.0+ß")), 0x0F0F, 0),
    (m.UpdateActivate(), 0x1010, 0),
    (m.UpdateActivating(m.SlotInfo(slot=1, state=m.SlotState.PENDING, security_counter=0x01020000,
                                   sha256=bytes(32), version="1.2.0")), 0x1010, 0),
    (m.UpdateConfirm(), 0x1111, 0),
    (m.UpdateConfirmed(m.SlotInfo(slot=1, state=m.SlotState.ACTIVE, security_counter=0xFFFFFFFF,
                                  sha256=b"\xff" * 32, version="")), 0x1111, 0),
    (m.UpdateStatus(), 0x1212, 0),
    (m.UpdateState(running_slot=1, boot_mode=m.BootMode.TRIAL, received=4096, size=0x00200123,
                   sha256=bytes(range(32)), security_counter=0x01010000,
                   slots=(m.SlotInfo(0, m.SlotState.STANDBY, 0x01010000, b"\xa5" * 32, "1.1.0"),
                          m.SlotInfo(1, m.SlotState.TRIAL, 0x01020000, b"\x5a" * 32, "1.2.0"))), 0x1212, 0),
]
BY_NAME = {type(msg).__name__: (msg, rid, flags) for msg, rid, flags in CASES}


def _jsonable(v):
    if isinstance(v, bool):
        return v
    if isinstance(v, enum.Enum):
        return int(v)
    if isinstance(v, (bytes, bytearray, memoryview)):
        return {"hex": bytes(v).hex()}
    if dataclasses.is_dataclass(v):
        return fields_json(v)
    if isinstance(v, (tuple, list)):
        return [_jsonable(x) for x in v]
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    return v


def fields_json(msg: m.Message) -> dict:
    return {f.name: _jsonable(getattr(msg, f.name)) for f in dataclasses.fields(msg) if f.compare}  # not derived views


def build_golden() -> dict:
    return {
        "_comment": "Protocol v1 golden frames. Regenerate ONLY for a deliberate protocol change: "
                    ".venv/bin/python -m tests.protocol.test_golden --regenerate",
        "protocol_version": list(VERSION),
        "vectors": [
            {"message": type(msg).__name__, "msg_type": f"0x{msg.TYPE:04x}", "request_id": rid, "flags": flags,
             "fields": fields_json(msg), "hex": m.encode(msg, rid, flags).hex()}
            for msg, rid, flags in CASES
        ],
    }


def load_golden() -> dict:
    return json.loads(GOLDEN.read_text(encoding="utf-8"))


VECTORS = load_golden()["vectors"] if GOLDEN.exists() else []
NAMES = [v["message"] for v in VECTORS]


def vector(name: str) -> dict:
    return next(v for v in VECTORS if v["message"] == name)


# -- coverage ----------------------------------------------------------------------------------
def test_every_message_class_has_exactly_one_vector() -> None:
    classes = sorted(cls.__name__ for cls in m.MESSAGES.values())
    assert len(classes) == 44  # v1.0: 20; v1.1 added the eight CALIB_* messages; v1.2 four repair, twelve UPDATE_*
    assert sorted(BY_NAME) == classes
    assert len(CASES) == len(BY_NAME)
    assert sorted(NAMES) == classes
    assert load_golden()["protocol_version"] == [1, 3]


def test_the_code_speaks_the_pinned_version() -> None:
    assert (VERSION_MAJOR, VERSION_MINOR) == VERSION == (1, 3)
    assert {(v["hex"][8:10], v["hex"][10:12]) for v in VECTORS} == {("01", "03")}


def test_info_is_the_v1_0_layout_plus_trailing_calibration_id_usb_speed_and_stage_limits() -> None:
    """A 1.0 host reads INFO unchanged: the 1.0 fields, then 4 + 1 bytes it ignores (SPEC §4.1, §11)."""
    info, _, _ = BY_NAME["Info"]
    p = bytes.fromhex(vector("Info")["hex"])[HEADER_LEN:-TRAILER_LEN]
    strings = b"".join(len(s.encode()).to_bytes(1, "little") + s.encode()
                       for s in (info.model, info.serial, info.firmware_version))
    v10_part = struct.pack("<BBIHHIHH", 1, 1, 0xA5A50F0F, 1280, 960, 1 << 20, 1280, 960) + strings
    limits = b"\x02" + bytes.fromhex("0100 0005 c003") + bytes.fromhex("0200 8002 e001")  # u16 stage, width, height
    assert p == v10_part + b"\x0d\xf0\xad\x8b" + b"\x00" + limits  # calibration_id 0x8BADF00D, u32 LE; usb_speed 0
    # as a 1.2 device sends it (no stage limits): read as none
    assert m.Info.unpack(p[:-len(limits)]) == dataclasses.replace(info, stage_limits=())
    # no trailing field: as a 1.0 device sends it
    assert m.Info.unpack(v10_part) == dataclasses.replace(info, calibration_id=0, stage_limits=())


@pytest.mark.parametrize("name", NAMES)
def test_vector_metadata_matches_the_instance(name: str) -> None:
    msg, rid, flags = BY_NAME[name]
    v = vector(name)
    assert v["msg_type"] == f"0x{m.MESSAGES[msg.TYPE].TYPE:04x}"
    assert (v["request_id"], v["flags"]) == (rid, flags)
    assert v["fields"] == fields_json(msg)


# -- encode / decode against the stored bytes --------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_encode_gives_the_golden_bytes(name: str) -> None:
    msg, rid, flags = BY_NAME[name]
    assert m.encode(msg, rid, flags).hex() == vector(name)["hex"]


@pytest.mark.parametrize("name", NAMES)
def test_decode_of_the_golden_bytes_gives_the_instance(name: str) -> None:
    msg, rid, flags = BY_NAME[name]
    wire = bytes.fromhex(vector(name)["hex"])
    dec = Decoder()
    packets = dec.feed(wire)
    assert packets == [Packet(msg.TYPE, rid, flags, msg.pack(), VERSION)]
    out = m.decode_packet(packets[0])
    assert type(out) is type(msg)
    assert out == msg
    assert out.pack() == wire[HEADER_LEN:-TRAILER_LEN]
    assert dec.buffered == 0
    assert dec.stats.packets == 1 and dec.stats.garbage_bytes == 0 and dec.stats.dropped == 0
    assert dec.stats.bytes_in == len(wire)


def test_all_golden_frames_back_to_back_decode_in_order() -> None:
    wire = b"".join(bytes.fromhex(v["hex"]) for v in VECTORS)
    dec = Decoder()
    packets = [p for i in range(0, len(wire), 7) for p in dec.feed(wire[i:i + 7])]
    assert [type(m.decode_packet(p)).__name__ for p in packets] == NAMES
    assert [m.decode_packet(p) for p in packets] == [BY_NAME[n][0] for n in NAMES]
    assert [p.request_id for p in packets] == [BY_NAME[n][1] for n in NAMES]
    assert dec.stats.packets == len(NAMES) and dec.stats.dropped == 0 and dec.stats.garbage_bytes == 0


# -- the layout, checked by hand rather than through the codec ---------------------------------
def test_crc_check_values() -> None:
    assert binascii.crc_hqx(b"123456789", 0xFFFF) == 0x29B1  # CRC-16/CCITT-FALSE
    assert zlib.crc32(b"123456789") == 0xCBF43926  # CRC-32 (IEEE)
    assert zlib.crc32(b"") == 0


@pytest.mark.parametrize("name", NAMES)
def test_header_and_trailer_fields_by_hand(name: str) -> None:
    msg, rid, flags = BY_NAME[name]
    wire = bytes.fromhex(vector(name)["hex"])
    payload = wire[20:-4]
    assert wire[0:4] == b"STOC"
    assert (wire[4], wire[5]) == (1, 3)  # version 1.3
    assert wire[6] == 20  # header_len
    assert wire[7] == flags
    assert int.from_bytes(wire[8:10], "little") == msg.TYPE
    assert int.from_bytes(wire[10:12], "little") == rid
    assert int.from_bytes(wire[12:16], "little") == len(payload) == len(wire) - 24
    assert wire[16:18] == b"\x00\x00"  # reserved
    assert int.from_bytes(wire[18:20], "little") == binascii.crc_hqx(wire[:18], 0xFFFF)
    assert int.from_bytes(wire[-4:], "little") == zlib.crc32(payload)


def test_little_endian_fields_literally() -> None:
    wire = bytes.fromhex(vector("SetConfig")["hex"])
    assert wire[:16] == b"STOC\x01\x03\x14\x01\x03\x00\x34\x12" + struct.pack("<I", 2 + 5 * 6)
    # payload: u16 count, then (u16 id, i32 value) pairs in insertion order
    assert wire[20:22] == b"\x05\x00"
    assert wire[22:28] == b"\x01\x00" + (1280).to_bytes(4, "little")
    assert wire[34:40] == b"\x0a\x00\xc0\xff\xff\xff"  # min_disparity id 10 = -64
    assert wire[40:46] == b"\x12\x00\xff\xff\xff\xff"  # disp12_max_diff id 18 = -1

    wire = bytes.fromhex(vector("GetInfo")["hex"])
    assert len(wire) == 24
    assert wire[:18] == b"STOC\x01\x03\x14\x00\x01\x00\x01\x00" + bytes(6)
    assert wire[20:] == bytes(4)  # CRC-32 of an empty payload

    wire = bytes.fromhex(vector("Trigger")["hex"])
    assert wire[8:12] == b"\x04\x00\xff\xff"

    wire = bytes.fromhex(vector("Triggered")["hex"])
    assert wire[8:16] == b"\x04\x80\xff\xff\x08\x00\x00\x00"
    assert wire[20:28] == b"\xef\xbe\xad\xde\x2a\x00\x00\x00"

    wire = bytes.fromhex(vector("Nack")["hex"])
    text = BY_NAME["Nack"][0].message.encode("utf-8")
    assert wire[8:12] == b"\xff\xff\x34\x12"
    assert wire[20:28] == b"\x03\x00\x04\x00\x08\x00" + len(text).to_bytes(2, "little")
    assert wire[28:-4] == text

    wire = bytes.fromhex(vector("FrameBegin")["hex"])
    assert wire[8:10] == b"\x01\x40"
    p = wire[20:-4]
    assert len(p) == 56
    assert p[0:4] == b"\x04\x03\x02\x01"  # sequence
    assert p[26:30] == b"\x07\x01\x01\x10"  # planes, flags, disparity_format, subpixel
    assert p[30:32] == b"\xe0\xff"  # min_disparity -32 as i16
    assert p[34:36] == b"\x00\x80"  # invalid_disparity -32768
    assert p[36:40] == b"\xee\xff\xc0\x00"  # calibration_id
    assert struct.unpack_from("<4f", p, 40) == (812.5, 319.75, -239.25, 0.0625)

    wire = bytes.fromhex(vector("FrameData")["hex"])
    assert wire[20:29] == b"\x04\x03\x02\x01\x04\x40\x23\x01\x00"
    assert wire[29:-4] == BY_NAME["FrameData"][0].data

    wire = bytes.fromhex(vector("Status")["hex"])
    p = wire[20:-4]
    assert p[:12] == bytes.fromhex("efcdab8967452301") + b"\x01\x01" + len(m.COUNTERS).to_bytes(2, "little")
    assert len(p) == 12 + 8 * len(m.COUNTERS)


def test_calibration_messages_literally() -> None:
    """SPEC §12 layouts, byte for byte."""
    wire = bytes.fromhex(vector("CalibRead")["hex"])
    assert wire[7:16] == b"\x01\x09\x00\x03\x02\x09\x00\x00\x00"  # flags RESEND, type, rid, payload_len 9
    assert wire[20:-4] == b"\x01" + b"\x03\x02\x01\x00" + b"\x00\xf0\x00\x00"  # factory, offset, length 61440

    wire = bytes.fromhex(vector("CalibData")["hex"])
    data = BY_NAME["CalibData"][0].data
    assert wire[8:16] == b"\x09\x80\x03\x02" + (17 + len(data)).to_bytes(4, "little")
    p = wire[20:-4]
    assert p[:17] == b"\x02" + b"\x04\x03\x02\x01" + b"\xbe\xba\xfe\xca" + b"\xf8\x00\x00\x00" + b"\xc8\x00\x00\x00"
    assert p[17:] == data  # the data runs to the end of the payload

    wire = bytes.fromhex(vector("CalibWrite")["hex"])
    p = wire[20:-4]
    assert wire[8:10] == b"\x0a\x00"
    assert p[:8] == b"\x00\xf0\x00\x00" + b"\x45\x23\x01\x00" and p[8:] == BY_NAME["CalibWrite"][0].data

    wire = bytes.fromhex(vector("CalibWritten")["hex"])
    assert wire[8:16] == b"\x0a\x80\x0a\xa0\x04\x00\x00\x00" and wire[20:-4] == b"\x1c\xf0\x00\x00"

    wire = bytes.fromhex(vector("CalibCommit")["hex"])
    assert wire[8:16] == b"\x0b\x00\x0b\x0b\x09\x00\x00\x00"
    assert wire[20:-4] == b"\x02" + b"\xf8\x00\x00\x00" + b"\xef\xbe\xad\xde"

    wire = bytes.fromhex(vector("CalibRestore")["hex"])
    assert len(wire) == 24 and wire[8:16] == b"\x0c\x00\xfe\xff" + bytes(4) and wire[20:] == bytes(4)

    committed = bytes.fromhex(vector("CalibCommitted")["hex"])
    assert committed[8:16] == b"\x0b\x80\x0b\x0b\x09\x00\x00\x00"
    assert committed[20:-4] == b"\x02" + b"\xee\xff\xc0\x00" + b"\x78\x56\x34\x12"
    restored = bytes.fromhex(vector("CalibRestored")["hex"])
    assert restored[8:16] == b"\x0c\x80\xfe\xff\x09\x00\x00\x00"
    assert restored[20:-4] == b"\x01" + b"\xff\xff\xff\xff" + b"\x01\x00\x00\x00"


def test_frame_repair_fields_literally() -> None:
    """SPEC §13 layouts, v1.2."""
    wire = bytes.fromhex(vector("SetFrameLink")["hex"])
    assert wire[8:16] == b"\x0d\x00\x0d\x0d\x04\x00\x00\x00" and wire[20:-4] == b"\x00\x04\x00\x00"
    wire = bytes.fromhex(vector("FrameLink")["hex"])
    assert wire[8:10] == b"\x0d\x80" and wire[20:-4] == b"\x00\x04\x00\x00" + b"\x08\x00"
    wire = bytes.fromhex(vector("FrameResend")["hex"])
    assert wire[7] == FLAG_RESEND and wire[8:16] == b"\x0e\x00\x0e\x0e\x17\x00\x00\x00"
    assert wire[20:-4] == (b"\x04\x03\x02\x01\x02" + b"\x01\x00\x04\x00\x00\x00\x04\x00\x00"
                           + b"\x04\x40\x23\x01\x00\xff\xff\x01\x00")
    wire = bytes.fromhex(vector("FrameResent")["hex"])
    assert wire[8:10] == b"\x0e\x80" and wire[20:-4] == b"\x04\x03\x02\x01\x00\x00\x21\x00\x00\x00"


SPEC_GET_INFO = "53 54 4f 43 01 03 14 00 01 00 01 00 00 00 00 00 00 00 fc f3 00 00 00 00"
SPEC_SET_CONFIG = "53 54 4f 43 01 03 14 00 03 00 02 00 08 00 00 00 00 00 41 e8 01 00 03 00 00 00 00 00 59 ad 1c 2f"
SPEC_NACK = ("53 54 4f 43 01 03 14 00 ff ff 02 00 1c 00 00 00 00 00 92 a4"
             "03 00 04 00 03 00 14 00 66 70 73 3d 30 20 6f 75 74 73 69 64 65 20 31 2e 2e 31 32 30"
             "3f 04 0b fe")
SPEC_CALIB_READ = ("53 54 4f 43 01 03 14 00 09 00 03 00 09 00 00 00 00 00 f3 7e"
                   "00 00 00 00 00 00 f0 00 00 7e 67 cd 53")


def test_spec_worked_examples() -> None:
    """protocol/SPEC.md §4.13, byte for byte."""
    assert m.encode(m.GetInfo(), 1) == bytes.fromhex(SPEC_GET_INFO)
    # the RESEND retry of it: flags 01, header CRC value 0xA173 (on the wire LE: 73 a1)
    retry = m.encode(m.GetInfo(), 1, FLAG_RESEND)
    assert retry[7] == 0x01 and int.from_bytes(retry[18:20], "little") == 0x2BB5
    assert int.from_bytes(bytes.fromhex(SPEC_GET_INFO)[18:20], "little") == 0xF3FC
    assert m.encode(m.SetConfig({3: 0}), 2) == bytes.fromhex(SPEC_SET_CONFIG)
    nack = bytes.fromhex(SPEC_NACK)
    assert m.encode(m.Nack(m.MsgType.SET_CONFIG, ErrorCode.OUT_OF_RANGE, 3, "fps=0 outside 1..120"), 2) == nack
    (p,) = Decoder().feed(nack)
    assert (p.msg_type, p.request_id) == (0xFFFF, 2)
    assert m.decode_packet(p) == m.Nack(3, 4, 3, "fps=0 outside 1..120")
    read = bytes.fromhex(SPEC_CALIB_READ)
    assert m.encode(m.CalibRead(m.CalibSource.ACTIVE, 0, m.MAX_CALIB_CHUNK), 3) == read
    assert int.from_bytes(read[18:20], "little") == 0x7EF3 and int.from_bytes(read[-4:], "little") == 0x53CD677E


@pytest.mark.parametrize("example", [SPEC_GET_INFO, SPEC_SET_CONFIG, SPEC_NACK, SPEC_CALIB_READ],
                         ids=["GET_INFO", "SET_CONFIG", "NACK", "CALIB_READ"])
def test_spec_shows_the_worked_examples(example: str) -> None:
    """The bytes above are the ones SPEC.md §4.13 prints (whitespace, '|' and backticks ignored)."""
    text = SPEC.read_text(encoding="utf-8").lower()
    section = text[text.index("### §4.13"):text.index("## §5")]
    flat = "".join(ch for ch in section if ch not in " \t\n|`")
    assert example.replace(" ", "") in flat


def test_spec_names_the_version() -> None:
    text = SPEC.read_text(encoding="utf-8")
    assert f"Protocol version **{VERSION[0]}.{VERSION[1]}**" in text


def regenerate() -> None:
    GOLDEN.parent.mkdir(parents=True, exist_ok=True)
    GOLDEN.write_text(json.dumps(build_golden(), indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    print(f"wrote {GOLDEN}")


if __name__ == "__main__":
    if sys.argv[1:] != ["--regenerate"]:
        sys.exit(__doc__)
    regenerate()
