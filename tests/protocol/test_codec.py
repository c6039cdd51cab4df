"""Protocol v1 codec: message round trips, the resynchronising Decoder, fuzzing, the parameter table.

The decoder's behaviour is the algorithm of protocol/SPEC.md §3: every rejection (header CRC,
header_len, foreign major, oversize, payload CRC) counts one event and drops exactly ONE byte
before rescanning; nothing rejected is ever buffered. Hence the exact byte accounting used below:
bytes_in == bytes of delivered frames + garbage_bytes + dropped (one per rejection) + buffered.

Unit tests plus hypothesis properties; every property runs a modest number of examples so the
whole file stays well under 30 s on a shared two-core machine.
"""
from __future__ import annotations

import binascii
import dataclasses
import struct
import zlib

import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from stereocam.protocol import messages as m
from stereocam.protocol.errors import ErrorCode, ProtocolError
from stereocam.protocol.framing import (
    FLAG_RESEND, HEADER_LEN, MAGIC, MAX_HEADER_LEN, MAX_PAYLOAD, TRAILER_LEN, Decoder,
    VERSION_MAJOR, VERSION_MINOR, DecoderStats, Packet, encode_frame, header_crc,
)
from stereocam.protocol.messages import UnknownMessageError, decode_packet
from stereocam.protocol.params import BY_ID, BY_NAME, PARAMS, VALUE_NAMES, Param, defaults

FAST = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
FUZZ = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
LIGHT = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


# -- helpers -----------------------------------------------------------------------------------
def raw_frame(msg_type: int, request_id: int = 0, payload: bytes = b"", *, flags: int = 0, major: int = 1,
              minor: int = VERSION_MINOR, header_len: int = HEADER_LEN, payload_len: int | None = None,
              ext: bytes | None = None) -> bytes:
    """A frame built by hand (not through encode_frame), with a correct header CRC for whatever it claims."""
    ext = bytes(header_len - HEADER_LEN) if ext is None else ext
    plen = len(payload) if payload_len is None else payload_len
    head = struct.pack("<4sBBBBHHIH", MAGIC, major, minor, header_len, flags, msg_type, request_id, plen, 0)
    head += binascii.crc_hqx(head, 0xFFFF).to_bytes(2, "little")
    return head + ext + payload + zlib.crc32(ext + payload).to_bytes(4, "little")


def feed_chunks(dec: Decoder, data: bytes, sizes: list[int]) -> list[Packet]:
    """Feed ``data`` in chunks whose sizes cycle through ``sizes`` (all >= 1)."""
    out: list[Packet] = []
    pos = i = 0
    while pos < len(data):
        n = sizes[i % len(sizes)]
        out += dec.feed(data[pos:pos + n])
        pos += n
        i += 1
    return out


def feed_cut(dec: Decoder, data: bytes, cuts: list[int]) -> list[Packet]:
    """Feed ``data`` split at the given offsets (any order, duplicates give empty chunks)."""
    bounds = [0, *sorted(c % (len(data) + 1) for c in cuts), len(data)]
    out: list[Packet] = []
    for a, b in zip(bounds, bounds[1:]):
        out += dec.feed(data[a:b])
    return out


def spurious_valid_header(stream: bytes, real_starts: set[int]) -> bool:
    """True if a MAGIC outside ``real_starts`` happens to carry a valid header CRC (p ~ 2**-16 each)."""
    i = stream.find(MAGIC)
    while i >= 0:
        if i not in real_starts and i + HEADER_LEN <= len(stream) and \
                header_crc(stream[i:i + 18]) == int.from_bytes(stream[i + 18:i + 20], "little"):
            return True
        i = stream.find(MAGIC, i + 1)
    return False


def assert_every_byte_accounted(dec: Decoder, packets: list[Packet]) -> None:
    """SPEC §3 accounting (valid while every delivered frame has header_len 20)."""
    s = dec.stats
    assert s.packets == len(packets)
    assert s.bytes_in == sum(HEADER_LEN + len(p.payload) + TRAILER_LEN for p in packets) + s.garbage_bytes + \
        s.dropped + dec.buffered, s


def packet_of(msg: m.Message, rid: int = 0, flags: int = 0) -> Packet:
    return Packet(msg.TYPE, rid, flags, msg.pack(), (VERSION_MAJOR, VERSION_MINOR))  # what this code sends


# -- strategies --------------------------------------------------------------------------------
def uint(bits: int) -> st.SearchStrategy[int]:
    return st.integers(0, (1 << bits) - 1)


def sint(bits: int) -> st.SearchStrategy[int]:
    return st.integers(-(1 << (bits - 1)), (1 << (bits - 1)) - 1)


u8, u16, u32, u64 = uint(8), uint(16), uint(32), uint(64)
i16, i32 = sint(16), sint(32)
# float32-representable values: draw any finite double, round it through struct's f32 (values beyond
# the f32 range would overflow: clamp them first). NaN is excluded only because NaN != NaN.
f32 = st.floats(allow_nan=False, min_value=-3.4e38, max_value=3.4e38).map(
    lambda x: struct.unpack("<f", struct.pack("<f", x))[0]) | st.sampled_from([float("inf"), float("-inf"), -0.0])
short_str = st.text(max_size=60)  # <= 240 UTF-8 bytes: fits the u8 length prefix
param_values = st.dictionaries(u16, i32, max_size=24)
sha = st.binary(min_size=32, max_size=32)
slot_info = st.builds(m.SlotInfo, slot=u8, state=u8, security_counter=u32, sha256=sha, version=short_str)

MESSAGE_STRATEGIES: dict[type[m.Message], st.SearchStrategy[m.Message]] = {
    m.GetInfo: st.just(m.GetInfo()),
    m.GetConfig: st.just(m.GetConfig()),
    m.SetConfig: st.builds(m.SetConfig, param_values),
    m.Trigger: st.just(m.Trigger()),
    m.Start: st.just(m.Start()),
    m.Stop: st.just(m.Stop()),
    m.Heartbeat: st.just(m.Heartbeat()),
    m.TimeSync: st.just(m.TimeSync()),
    m.Info: st.builds(m.Info, model=short_str, serial=short_str, firmware_version=short_str,
                      protocol_version=st.tuples(u8, u8), capabilities=u32, sensor_width=u16, sensor_height=u16,
                      max_payload=u32, max_width=u16, max_height=u16, calibration_id=u32, usb_speed=u8,
                      stage_limits=st.lists(st.tuples(u16, u16, u16), max_size=3).map(tuple)),
    m.Config: st.builds(m.Config, param_values),
    m.ConfigApplied: st.builds(m.ConfigApplied, param_values),
    m.Triggered: st.builds(m.Triggered, trigger_id=u32, sequence=u32),
    m.Started: st.just(m.Started()),
    m.Stopped: st.just(m.Stopped()),
    m.Status: st.builds(m.Status, uptime_us=u64, streaming=st.booleans(), trigger_mode=u8,
                        counters=st.fixed_dictionaries({name: u64 for name in m.COUNTERS})),
    m.Time: st.builds(m.Time, device_time_us=u64),
    m.Nack: st.builds(m.Nack, request_type=u16, code=u16, param_id=u16, message=st.text(max_size=200)),
    m.FrameBegin: st.builds(m.FrameBegin, sequence=u32, trigger_id=u32, device_time_us=u64, exposure_us=u32,
                            gain=u16, width=u16, height=u16, planes=u8, flags=u8, disparity_format=u8, subpixel=u8,
                            min_disparity=i16, num_disparities=u16, invalid_disparity=i16, calibration_id=u32,
                            focal_px=f32, cx=f32, cy=f32, baseline_m=f32),
    m.FrameData: st.builds(m.FrameData, sequence=u32, plane=u8, offset=u32, data=st.binary(max_size=64)),
    m.FrameEnd: st.builds(m.FrameEnd, sequence=u32, status=u8, left_bytes=u32, right_bytes=u32,
                          disparity_bytes=u32),
    # v1.1 calibration storage (SPEC §12); sources / targets drawn beyond the defined values on purpose:
    # the codec carries any u8, the device judges it
    m.CalibRead: st.builds(m.CalibRead, source=u8, offset=u32, length=u32),
    m.CalibData: st.builds(m.CalibData, source=u8, generation=u32, calibration_id=u32, total=u32, offset=u32,
                           data=st.binary(max_size=300)),
    m.CalibWrite: st.builds(m.CalibWrite, offset=u32, total=u32, data=st.binary(max_size=300)),
    m.CalibWritten: st.builds(m.CalibWritten, staged=u32),
    m.CalibCommit: st.builds(m.CalibCommit, target=u8, total=u32, crc=u32),
    m.CalibRestore: st.just(m.CalibRestore()),
    m.CalibCommitted: st.builds(m.CalibCommitted, source=u8, generation=u32, calibration_id=u32),
    m.CalibRestored: st.builds(m.CalibRestored, source=u8, generation=u32, calibration_id=u32),
    # v1.2 frame repair (SPEC §13)
    m.SetFrameLink: st.builds(m.SetFrameLink, chunk_size=u32),
    m.FrameLink: st.builds(m.FrameLink, chunk_size=u32, kept_captures=u16),
    m.FrameResend: st.builds(m.FrameResend, sequence=u32,
                             ranges=st.lists(st.tuples(u8, u32, u32), max_size=20).map(tuple)),
    m.FrameResent: st.builds(m.FrameResent, sequence=u32, result=u8, frame_status=u8, chunks=u32),
    # v1.2 firmware update (SPEC §14)
    m.UpdateBegin: st.builds(m.UpdateBegin, size=u32, sha256=sha, flags=u8),
    m.UpdateBegun: st.builds(m.UpdateBegun, slot=u8, received=u32, size=u32),
    m.UpdateData: st.builds(m.UpdateData, offset=u32, data=st.binary(max_size=300)),
    m.UpdateWritten: st.builds(m.UpdateWritten, slot=u8, received=u32, size=u32),
    m.UpdateVerify: st.just(m.UpdateVerify()),
    m.UpdateVerified: st.builds(m.UpdateVerified, slot_info),
    m.UpdateActivate: st.just(m.UpdateActivate()),
    m.UpdateActivating: st.builds(m.UpdateActivating, slot_info),
    m.UpdateConfirm: st.just(m.UpdateConfirm()),
    m.UpdateConfirmed: st.builds(m.UpdateConfirmed, slot_info),
    m.UpdateStatus: st.just(m.UpdateStatus()),
    m.UpdateState: st.builds(m.UpdateState, running_slot=u8, boot_mode=u8, received=u32, size=u32, sha256=sha,
                             security_counter=u32, slots=st.lists(slot_info, max_size=3).map(tuple)),
}
any_message = st.one_of(*MESSAGE_STRATEGIES.values())
framed = st.tuples(any_message, u16, u8)  # (message, request_id, flags)
frame_lists = st.lists(framed, min_size=1, max_size=6)


def encode_all(items: list[tuple[m.Message, int, int]]) -> list[bytes]:
    return [m.encode(msg, rid, flags) for msg, rid, flags in items]


def test_strategies_cover_every_message_class() -> None:
    assert set(MESSAGE_STRATEGIES) == set(m.MESSAGES.values())


# -- message round trips -----------------------------------------------------------------------
@pytest.mark.parametrize("cls", list(m.MESSAGES.values()), ids=lambda c: c.__name__)
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_round_trip_every_message_type(cls: type[m.Message], data: st.DataObject) -> None:
    msg = data.draw(MESSAGE_STRATEGIES[cls])
    rid, flags = data.draw(u16), data.draw(u8)
    wire = m.encode(msg, rid, flags)
    assert len(wire) == HEADER_LEN + len(msg.pack()) + TRAILER_LEN
    dec = Decoder()
    packets = dec.feed(wire)
    assert packets == [packet_of(msg, rid, flags)]
    out = decode_packet(packets[0])
    assert type(out) is cls
    assert out == msg
    assert out.pack() == msg.pack()
    assert dec.buffered == 0 and dec.stats.packets == 1 and dec.stats.dropped == 0


def test_round_trip_of_signed_and_extreme_values() -> None:
    msg = m.FrameBegin(0xFFFFFFFF, 0, (1 << 64) - 1, 0, 0xFFFF, 0, 1, 0xFF, 0, 1, 16, -32768, 0xFFFF, 32767,
                       0xFFFFFFFF, float("inf"), -0.0, 3.4028234663852886e38, 1.401298464324817e-45)
    assert decode_packet(packet_of(msg)) == msg
    cfg = m.SetConfig({0: -(1 << 31), 0xFFFF: (1 << 31) - 1, 10: -256})
    assert decode_packet(packet_of(cfg)).values == {0: -(1 << 31), 0xFFFF: (1 << 31) - 1, 10: -256}
    with pytest.raises(struct.error):
        m.SetConfig({1: 1 << 31}).pack()  # not an int32: refused when packing
    nack = m.Nack(3, 4, 8, "zu groß — 範囲外 ✗ 📷")
    assert decode_packet(packet_of(nack, 0xFFFF)) == nack


def test_status_unpack_fills_every_counter_name() -> None:
    st_msg = m.Status(5, False, 2, {"frames_sent": 7})
    out = decode_packet(packet_of(st_msg))
    assert out.counters == {**{n: 0 for n in m.COUNTERS}, "frames_sent": 7}
    assert (out.uptime_us, out.streaming, out.trigger_mode) == (5, False, 2)
    # a newer device sending more counters than this code knows: kept under generic names
    payload = struct.pack("<QBBH", 1, 1, 0, len(m.COUNTERS) + 2) + struct.pack(f"<{len(m.COUNTERS) + 2}Q",
                                                                               *range(len(m.COUNTERS) + 2))
    out = decode_packet(Packet(m.MsgType.STATUS, 0, 0, payload))
    n = len(m.COUNTERS)
    assert out.counters[f"counter_{n}"] == n and out.counters[f"counter_{n + 1}"] == n + 1
    assert out.counters["frames_captured"] == 0 and len(out.counters) == n + 2


def test_overlong_strings_are_truncated_at_the_byte_limit() -> None:
    """SPEC §4.0: senders truncate at the byte limit (u8 for INFO, u16 for NACK); receivers replace bad UTF-8."""
    model = "é" * 200  # 400 UTF-8 bytes > 255
    payload = m.Info(model, "x" * 300, "fw", (1, 0), 0, 0, 0, 0, 0, 0).pack()
    assert payload[18] == 255 and payload[19:19 + 255] == model.encode()[:255]
    out = decode_packet(Packet(m.MsgType.INFO, 0, 0, payload))
    assert out.model == "é" * 127 + "\ufffd"  # the split 2-byte character is replaced
    assert out.serial == "x" * 255 and out.firmware_version == "fw"
    text = "ab" * 40_000
    out = decode_packet(packet_of(m.Nack(1, 2, 0, text)))
    assert out.message == text[:65535]


@pytest.mark.parametrize("cls", [m.Info, m.Nack, m.Status, m.UpdateState], ids=lambda c: c.__name__)
def test_trailing_fields_tolerated_where_spec_allows(cls) -> None:
    """SPEC §11: a v1.x sender may append fields to INFO (after v1.1's calibration_id), NACK, STATUS and
    (1.2) UPDATE_STATE."""
    msg = SAMPLES[cls]
    assert decode_packet(Packet(cls.TYPE, 0, 0, msg.pack() + b"\x01\x02new fields")) == msg


# -- INFO across minor versions (SPEC §4.1, §11) -----------------------------------------------
def info_v10_payload(major: int = 1, minor: int = 0, model: bytes = b"STOC-SIM", serial: bytes = b"SIM00007",
                     fw: bytes = b"1.0.0") -> bytes:
    """An INFO payload exactly as a v1.0 device sends it, built by hand from SPEC §4.1 (no calibration_id)."""
    head = struct.pack("<BBIHHIHH", major, minor, 0x0F, 1280, 960, MAX_PAYLOAD, 1280, 960)
    return head + b"".join(len(s).to_bytes(1, "little") + s for s in (model, serial, fw))


V10_INFO = m.Info("STOC-SIM", "SIM00007", "1.0.0", (1, 0), 0x0F, 1280, 960, MAX_PAYLOAD, 1280, 960)


def test_info_from_a_v1_0_device_decodes_with_calibration_id_0() -> None:
    out = decode_packet(Packet(m.MsgType.INFO, 1, 0, info_v10_payload(), (1, 0)))
    assert out == V10_INFO and out.calibration_id == 0
    # the same through the whole receive path: a 1.0 frame (ver_minor 0 in the header) is accepted
    dec = Decoder()
    (pkt,) = dec.feed(raw_frame(m.MsgType.INFO, 1, info_v10_payload(), minor=0))
    assert pkt.version == (1, 0) and decode_packet(pkt) == V10_INFO
    assert dec.stats.dropped == 0


def test_info_from_a_v1_1_device_carries_calibration_id() -> None:
    payload = info_v10_payload(minor=1) + b"\x78\x56\x34\x12"
    out = decode_packet(Packet(m.MsgType.INFO, 1, 0, payload))
    assert out == dataclasses.replace(V10_INFO, protocol_version=(1, 1), calibration_id=0x12345678)
    assert out.pack() == payload + b"\x00\x00"  # this sender always writes its fields (usb_speed, n_limits), 0 included
    uncalibrated = dataclasses.replace(out, calibration_id=0)
    assert uncalibrated.pack() == info_v10_payload(minor=1) + bytes(6)
    assert m.Info("a", "b", "c", (1, 1), 0, 0, 0, 0, 0, 0).calibration_id == 0  # the default


@pytest.mark.parametrize("tail, calibration_id, usb_speed", [
    (b"", 0, 0),  # 1.0 device: fields absent
    (b"\x01", 0, 0), (b"\x01\x02", 0, 0), (b"\x01\x02\x03", 0, 0),  # fewer than 4 bytes: taken as absent
    (b"\x01\x02\x03\x04", 0x04030201, 0),  # 1.1 device: no usb_speed
    (b"\xff\xff\xff\xff", 0xFFFFFFFF, 0),
    (b"\x01\x02\x03\x04\x03", 0x04030201, m.UsbSpeed.HIGH),  # 1.2 device on a USB 2.0 link
    (b"\x01\x02\x03\x04\x04\x00later v1.x fields", 0x04030201, m.UsbSpeed.SUPER),  # later fields: ignored
])
def test_info_trailing_calibration_id_and_usb_speed(tail: bytes, calibration_id: int, usb_speed: int) -> None:
    out = decode_packet(Packet(m.MsgType.INFO, 0, 0, info_v10_payload() + tail))
    assert out == dataclasses.replace(V10_INFO, calibration_id=calibration_id, usb_speed=usb_speed)


@LIGHT
@given(msg=MESSAGE_STRATEGIES[m.Info])
def test_info_without_its_trailing_fields_is_the_older_message(msg: m.Info) -> None:
    """INFO is the 1.0 INFO plus 4 bytes (1.1) plus 1 (1.2) plus 1 + 6n (1.3): what an older host
    reads of it is unchanged."""
    payload = msg.pack()
    limits = 1 + 6 * len(msg.stage_limits)
    assert payload[-5 - limits:-limits] == struct.pack("<IB", msg.calibration_id, msg.usb_speed)
    v12 = payload[:-limits]
    assert decode_packet(Packet(m.MsgType.INFO, 0, 0, v12[:-5])) == dataclasses.replace(
        msg, calibration_id=0, usb_speed=0, stage_limits=())
    assert decode_packet(Packet(m.MsgType.INFO, 0, 0, v12[:-1])) == dataclasses.replace(msg, usb_speed=0,
                                                                                        stage_limits=())
    assert decode_packet(Packet(m.MsgType.INFO, 0, 0, v12)) == dataclasses.replace(msg, stage_limits=())
    assert decode_packet(Packet(m.MsgType.INFO, 0, 0, payload)) == msg


def test_info_strings_must_still_fit_before_calibration_id() -> None:
    """The trailing field does not rescue a string length running past the payload."""
    payload = info_v10_payload()
    assert payload[18] == 8  # len("STOC-SIM")
    # fw claims 9 bytes, 5 are there: the 4 bytes of calibration_id must not be taken as the rest of it
    bad = payload[:-6] + b"\x09" + payload[-5:] + bytes(4)
    with pytest.raises(ProtocolError, match="Info.*string runs past the payload"):
        decode_packet(Packet(m.MsgType.INFO, 0, 0, bad[:-4]))
    assert decode_packet(Packet(m.MsgType.INFO, 0, 0, bad)).firmware_version == "1.0.0\x00\x00\x00\x00"


# -- calibration messages (SPEC §12) -----------------------------------------------------------
def test_calibration_types_sources_and_codes() -> None:
    assert {t.name: int(t) for t in m.MsgType if t.name.startswith("CALIB")} == {
        "CALIB_READ": 0x0009, "CALIB_WRITE": 0x000A, "CALIB_COMMIT": 0x000B, "CALIB_RESTORE": 0x000C,
        "CALIB_DATA": 0x8009, "CALIB_WRITTEN": 0x800A, "CALIB_COMMITTED": 0x800B, "CALIB_RESTORED": 0x800C}
    assert {int(k): v for k, v in m.REPLIES.items() if 0x0009 <= k <= 0x000C} == {
        0x0009: m.CalibData, 0x000A: m.CalibWritten, 0x000B: m.CalibCommitted, 0x000C: m.CalibRestored}
    for req, reply in m.REPLIES.items():
        assert reply.TYPE == m.reply_type(req) and m.MESSAGES[req].TYPE == req
    assert [(s.name, int(s)) for s in m.CalibSource] == [("ACTIVE", 0), ("FACTORY", 1), ("USER", 2)]
    assert int(ErrorCode.STORAGE) == 9
    assert m.MAX_CALIB_CHUNK == 61440


def test_update_types_replies_and_codes() -> None:
    """SPEC §14: requests 0x000F..0x0014 (after frame repair's 0x000D, 0x000E), replies request | 0x8000;
    error code 10."""
    assert {int(k): v for k, v in m.REPLIES.items() if k >= 0x000F} == {
        0x000F: m.UpdateBegun, 0x0010: m.UpdateWritten, 0x0011: m.UpdateVerified, 0x0012: m.UpdateActivating,
        0x0013: m.UpdateConfirmed, 0x0014: m.UpdateState}
    assert int(ErrorCode.IMAGE_REJECTED) == 10 and max(ErrorCode) is ErrorCode.IMAGE_REJECTED
    assert m.Capability.FIRMWARE_UPDATE == 0x80
    assert m.MAX_UPDATE_CHUNK + 4 <= MAX_PAYLOAD


def test_max_calib_chunk_fits_one_frame() -> None:
    body = bytes(range(256)) * (m.MAX_CALIB_CHUNK // 256)
    for msg in (m.CalibData(m.CalibSource.USER, 1, 2, 3 * len(body), len(body), body),
                m.CalibWrite(len(body), 3 * len(body), body)):
        wire = m.encode(msg, 7)
        assert len(wire) <= HEADER_LEN + MAX_PAYLOAD + TRAILER_LEN
        (pkt,) = Decoder().feed(wire)
        out = decode_packet(pkt)
        assert out == msg and type(out.data) is bytes and out.data == body


@LIGHT
@given(source=u8, generation=u32, calibration_id=u32)
def test_committed_and_restored_share_the_calib_state_layout(source, generation, calibration_id) -> None:
    a = m.CalibCommitted(source, generation, calibration_id)
    b = m.CalibRestored(source, generation, calibration_id)
    assert a.pack() == b.pack() == struct.pack("<BII", source, generation, calibration_id)
    assert isinstance(a, m.CalibState) and isinstance(b, m.CalibState) and a.TYPE != b.TYPE
    assert decode_packet(Packet(m.MsgType.CALIB_RESTORED, 0, 0, a.pack())) == b
    assert decode_packet(Packet(m.MsgType.CALIB_COMMITTED, 0, 0, b.pack())) == a


@LIGHT
@given(source=u8, generation=u32, calibration_id=u32, total=u32, offset=u32, data=st.binary(max_size=200))
def test_calib_data_layout(source, generation, calibration_id, total, offset, data) -> None:
    payload = struct.pack("<BIIII", source, generation, calibration_id, total, offset) + data
    out = decode_packet(Packet(m.MsgType.CALIB_DATA, 0, 0, payload))
    assert out == m.CalibData(source, generation, calibration_id, total, offset, data)
    assert out.pack() == payload


@LIGHT
@given(offset=u32, total=u32, data=st.binary(max_size=200))
def test_calib_write_layout(offset, total, data) -> None:
    payload = struct.pack("<II", offset, total) + data
    out = decode_packet(Packet(m.MsgType.CALIB_WRITE, 0, 0, payload))
    assert out == m.CalibWrite(offset, total, data) and out.pack() == payload


def test_calib_head_only_payloads_carry_no_data() -> None:
    """CALIB_DATA with no data is what a device sends when nothing is stored (source 0) or past the end."""
    none = m.CalibData(m.CalibSource.ACTIVE, 0, 0, 0, 0, b"")
    assert none.pack() == bytes(17)
    assert decode_packet(Packet(m.MsgType.CALIB_DATA, 0, 0, bytes(17))) == none
    assert decode_packet(Packet(m.MsgType.CALIB_WRITE, 0, 0, bytes(8))) == m.CalibWrite(0, 0, b"")


@pytest.mark.parametrize("cls, size", [(m.CalibRead, 9), (m.CalibWritten, 4), (m.CalibCommit, 9),
                                       (m.CalibCommitted, 9), (m.CalibRestored, 9), (m.CalibData, 17),
                                       (m.CalibWrite, 8)], ids=lambda x: getattr(x, "__name__", str(x)))
@LIGHT
@given(payload=st.binary(max_size=40))
def test_malformed_calibration_payloads(cls, size: int, payload: bytes) -> None:
    """Fixed layouts need their exact size; head + data layouts need at least the head."""
    fixed = cls not in (m.CalibData, m.CalibWrite)
    ok = len(payload) == size if fixed else len(payload) >= size
    try:
        out = decode_packet(Packet(cls.TYPE, 0, 0, payload))
    except ProtocolError as exc:
        assert not ok and cls.__name__ in str(exc) and f"({len(payload)} bytes)" in str(exc)
        assert not isinstance(exc, UnknownMessageError)
    else:
        assert ok and type(out) is cls and out.pack() == payload


def test_calibration_fields_out_of_range_are_refused_when_packing() -> None:
    for bad in (m.CalibRead(256, 0, 0), m.CalibRead(0, 1 << 32, 0), m.CalibCommit(-1, 0, 0),
                m.CalibWrite(0, -1, b""), m.CalibWritten(1 << 32), m.CalibRestored(0, 1 << 32, 0),
                m.CalibData(0, 0, 1 << 32, 0, 0, b"")):
        with pytest.raises(struct.error):
            bad.pack()


# -- decoder: chunking -------------------------------------------------------------------------
@FAST
@given(items=st.lists(framed, min_size=1, max_size=12), cuts=st.lists(st.integers(0, 10_000), max_size=40))
def test_decoder_returns_the_frames_in_order_for_any_chunking(items, cuts) -> None:
    stream = b"".join(encode_all(items))
    dec = Decoder()
    packets = feed_cut(dec, stream, cuts)
    assert packets == [packet_of(msg, rid, flags) for msg, rid, flags in items]
    assert dec.buffered == 0
    assert dec.stats.as_dict() == {**DecoderStats().as_dict(), "bytes_in": len(stream), "packets": len(items)}


@FAST
@given(items=frame_lists, size=st.integers(1, 64))
def test_decoder_fixed_chunk_sizes(items, size) -> None:
    stream = b"".join(encode_all(items))
    dec = Decoder()
    assert feed_chunks(dec, stream, [size]) == [packet_of(msg, rid, flags) for msg, rid, flags in items]
    assert dec.buffered == 0 and dec.stats.packets == len(items)


def test_decoder_one_byte_at_a_time() -> None:
    items = [(m.Nack(1, 2, 3, "über"), 0x1234, 0), (m.Heartbeat(), 1, FLAG_RESEND),
             (m.FrameData(9, 4, 100, MAGIC * 5), 0, 0), (m.Time(2 ** 63), 0xFFFF, 0)]
    stream = b"".join(encode_all(items))
    dec = Decoder()
    seen = []
    for i in range(len(stream)):
        got = dec.feed(stream[i:i + 1])
        seen += [(i, p) for p in got]
        assert dec.buffered <= MAX_HEADER_LEN + 64 + TRAILER_LEN
    ends = [sum(len(f) for f in encode_all(items[:k + 1])) - 1 for k in range(len(items))]
    assert seen == [(e, packet_of(msg, rid, fl)) for e, (msg, rid, fl) in zip(ends, items)]  # each on its last byte
    assert dec.feed(b"") == [] and dec.stats.bytes_in == len(stream)


# -- decoder: garbage and corruption -----------------------------------------------------------
garbage = st.lists(st.one_of(st.binary(max_size=40),
                             st.sampled_from([MAGIC, b"STO", b"ST", b"S", MAGIC + b"\x01\x00\x14", MAGIC * 2])),
                   max_size=5).map(b"".join)


@FAST
@given(items=frame_lists, junk=st.lists(garbage, min_size=7, max_size=7), size=st.integers(1, 50))
def test_garbage_between_frames_is_skipped_and_counted(items, junk, size) -> None:
    frames = encode_all(items)
    stream, starts = b"", set()
    for g, f in zip(junk, frames):
        stream += g
        starts.add(len(stream))
        stream += f
    assume(not spurious_valid_header(stream, starts))
    total_junk = sum(len(g) for g in junk[:len(frames)])
    dec = Decoder()
    out = feed_chunks(dec, stream, [size])
    assert out == [packet_of(msg, rid, flags) for msg, rid, flags in items]
    s = dec.stats
    assert s.packets == len(items) and dec.buffered == 0
    assert s.bad_headers == s.payload_crc_errors == s.oversize == s.unsupported_version == 0
    assert s.header_crc_errors <= stream.count(MAGIC) - len(frames)  # at most one per false magic
    # SPEC §3: a rejected candidate costs one byte (counted as the error), the rest is garbage
    assert s.garbage_bytes + s.header_crc_errors == total_junk
    assert_every_byte_accounted(dec, out)


@FAST
@given(items=frame_lists, junk=st.binary(max_size=60))
def test_garbage_without_magic_is_counted_exactly(items, junk) -> None:
    frames = encode_all(items)
    stream = junk + junk.join(frames)
    assume(stream.count(MAGIC) == len(frames))  # neither the junk nor its seams with frames spell a magic
    dec = Decoder()
    assert feed_chunks(dec, stream, [7]) == [packet_of(msg, rid, flags) for msg, rid, flags in items]
    assert dec.stats.garbage_bytes == len(junk) * len(frames)
    assert dec.stats.dropped == 0


def test_trailing_partial_magic_is_held_back_until_resolved() -> None:
    f = m.encode(m.Heartbeat(), 3)
    dec = Decoder()
    assert dec.feed(b"xyzST") == [] and dec.buffered == 3 and dec.stats.garbage_bytes == 2  # "zST" may start a magic
    assert dec.feed(b"O") == [] and dec.buffered == 3 and dec.stats.garbage_bytes == 3
    assert dec.feed(b"!") == [] and dec.buffered == 3 and dec.stats.garbage_bytes == 4  # "STO!" was not magic
    assert dec.feed(f) == [packet_of(m.Heartbeat(), 3)]
    assert dec.stats.garbage_bytes == 7 and dec.buffered == 0


def test_every_dropped_byte_is_accounted_for() -> None:
    good = m.encode(m.Time(123), 9)
    bad_payload = bytearray(m.encode(m.Triggered(1, 2), 8))
    bad_payload[-1] ^= 0xFF
    junk = b"xx" + MAGIC + bytes(range(30))  # a magic whose header CRC fails
    oversize = encode_frame(m.MsgType.FRAME_DATA, 0, bytes(40))
    foreign = raw_frame(m.MsgType.TIME, 0, bytes(8), major=3)
    bad_hlen = raw_frame(m.MsgType.TIME, 0, bytes(8), header_len=HEADER_LEN)
    bad_hlen = bad_hlen[:6] + b"\x13" + bad_hlen[7:18]
    bad_hlen += header_crc(bad_hlen).to_bytes(2, "little") + bytes(12)
    parts = [junk, good, bytes(bad_payload), good, oversize, good, foreign, good, bad_hlen, good]
    dec = Decoder(max_payload=32)
    out = dec.feed(b"".join(parts))
    assert out == [packet_of(m.Time(123), 9)] * 5
    s = dec.stats
    assert (s.header_crc_errors, s.payload_crc_errors, s.oversize, s.unsupported_version, s.bad_headers) == \
        (1, 1, 1, 1, 1)
    assert s.dropped == 5
    assert s.garbage_bytes == len(junk) + len(bad_payload) + len(oversize) + len(foreign) + len(bad_hlen) - 5
    assert_every_byte_accounted(dec, out)


@FAST
@given(items=st.lists(framed, min_size=2, max_size=5), data=st.data())
def test_one_corrupted_byte_drops_only_that_frame(items, data) -> None:
    frames = encode_all(items)
    k = data.draw(st.integers(0, len(frames) - 1), label="frame")
    off = data.draw(st.integers(0, len(frames[k]) - 1), label="offset")
    bad = bytearray(frames[k])
    bad[off] ^= data.draw(st.integers(1, 255), label="xor")
    frames[k] = bytes(bad)
    stream = b"".join(frames)
    starts = {sum(len(f) for f in frames[:i]) for i in range(len(frames)) if not (i == k and off < 4)}
    assume(stream.count(MAGIC) == len(starts))  # no payload / corruption spelling an extra magic
    assume(not spurious_valid_header(stream, starts))
    dec = Decoder()
    size = data.draw(st.integers(1, 40), label="chunk")
    expect = [packet_of(msg, rid, flags) for i, (msg, rid, flags) in enumerate(items) if i != k]
    out = feed_chunks(dec, stream, [size])
    assert out == expect
    s = dec.stats
    assert s.packets == len(items) - 1
    if off < 4:  # magic destroyed: the whole frame is garbage to the decoder
        assert (s.header_crc_errors, s.payload_crc_errors) == (0, 0)
    elif off < HEADER_LEN:
        assert (s.header_crc_errors, s.payload_crc_errors) == (1, 0)
    else:
        assert (s.header_crc_errors, s.payload_crc_errors) == (0, 1)
    assert s.bad_headers == s.oversize == s.unsupported_version == 0
    assert s.dropped == (0 if off < 4 else 1)
    # the damaged frame's bytes are garbage (minus the byte the rejection consumed), except that up to 3
    # bytes (a possible partial magic) stay buffered when it was the last frame
    assert s.garbage_bytes + s.dropped + dec.buffered == len(frames[k])
    assert dec.buffered == 0 if k < len(frames) - 1 else dec.buffered <= 3
    assert_every_byte_accounted(dec, out)


@FAST
@given(victim=framed, items=frame_lists, data=st.data())
def test_truncated_frame_followed_by_good_frames(victim, items, data) -> None:
    cut_frame = m.encode(*victim)
    cut = data.draw(st.integers(1, len(cut_frame) - 1), label="cut")
    frames = encode_all(items)
    # filler so that whatever length the truncated header announced, its "payload" is complete and fails the CRC
    filler = [m.encode(m.Heartbeat(), 0xAAAA)] * (len(cut_frame) // 24 + 2)
    stream = cut_frame[:cut] + b"".join(frames + filler)
    starts = {cut + sum(len(f) for f in (frames + filler)[:i]) for i in range(len(frames) + len(filler))}
    assume(stream.count(MAGIC) == len(starts) + (cut >= 4))
    assume(not spurious_valid_header(stream, starts))
    dec = Decoder()
    out = feed_chunks(dec, stream, [data.draw(st.integers(1, 64), label="chunk")])
    expect = ([packet_of(msg, rid, flags) for msg, rid, flags in items]
              + [packet_of(m.Heartbeat(), 0xAAAA)] * len(filler))
    assert out == expect
    s = dec.stats
    if cut < 4:
        assert s.dropped == 0 and s.garbage_bytes == cut
    elif cut < HEADER_LEN:
        assert (s.header_crc_errors, s.payload_crc_errors, s.dropped) == (1, 0, 1)
    else:
        assert (s.header_crc_errors, s.payload_crc_errors, s.dropped) == (0, 1, 1)
    assert dec.buffered == 0
    assert s.garbage_bytes + s.dropped == cut
    assert_every_byte_accounted(dec, out)


def test_truncated_frame_good_frame_comes_out_after_resync() -> None:
    big = m.encode(m.FrameData(1, 4, 0, bytes(200)), 0)
    good = m.encode(m.Triggered(5, 6), 0x1234)
    dec = Decoder()
    assert dec.feed(big[:100] + good) == []  # still waiting for the 228 bytes the header announced
    out = dec.feed(good * 4)
    assert out == [packet_of(m.Triggered(5, 6), 0x1234)] * 5
    assert dec.stats.payload_crc_errors == 1 and dec.stats.packets == 5 and dec.buffered == 0


# -- decoder: policy drops (oversize, foreign version, bad header_len) --------------------------
def test_oversize_frame_is_rejected_without_buffering() -> None:
    dec = Decoder(max_payload=1024)
    big = encode_frame(m.MsgType.FRAME_DATA, 0, bytes(range(256)) * 20)  # 5120 > 1024, no magic inside
    assert MAGIC not in big[4:]
    after = m.encode(m.Time(2), 2)
    stream = big + after
    out = []
    for i in range(0, len(stream), 100):
        out += dec.feed(stream[i:i + 100])
        if i + 100 <= len(big):
            assert dec.buffered <= 3  # only a possible partial magic is ever kept
            assert dec.stats.oversize == 1
    assert out == [packet_of(m.Time(2), 2)]
    s = dec.stats
    assert (s.oversize, s.packets, s.dropped, s.payload_crc_errors, s.header_crc_errors) == (1, 1, 1, 0, 0)
    assert s.garbage_bytes == len(big) - 1 and dec.buffered == 0
    assert_every_byte_accounted(dec, out)


def test_oversize_frame_in_a_single_chunk() -> None:
    dec = Decoder(max_payload=16)
    stream = encode_frame(m.MsgType.FRAME_DATA, 0, bytes(17)) + m.encode(m.Stop(), 5) + \
        encode_frame(m.MsgType.FRAME_DATA, 0, bytes(16))
    out = dec.feed(stream)
    assert [(p.msg_type, len(p.payload)) for p in out] == [(m.MsgType.STOP, 0), (m.MsgType.FRAME_DATA, 16)]
    assert dec.stats.oversize == 1 and dec.buffered == 0
    assert_every_byte_accounted(dec, out)


@pytest.mark.parametrize("major", [1, 2, 0, 255])
def test_a_huge_announced_length_never_holds_up_the_stream(major: int) -> None:
    """A valid header announcing 4 GiB (oversize, or any length in a foreign major) is rejected from
    the header alone: the next frame comes out at once, nothing is buffered."""
    head = raw_frame(m.MsgType.FRAME_DATA, 0, b"", major=major, payload_len=0xFFFFFFFF)[:HEADER_LEN]
    after = m.encode(m.Heartbeat(), 77)
    dec = Decoder()
    assert dec.feed(head) == [] and dec.buffered <= 3
    assert dec.feed(after) == [packet_of(m.Heartbeat(), 77)]
    s = dec.stats
    assert (s.oversize, s.unsupported_version) == ((1, 0) if major == 1 else (0, 1))
    assert s.garbage_bytes == HEADER_LEN - 1 and dec.buffered == 0


def test_header_announcing_more_than_max_payload_is_not_buffered() -> None:
    """Default limit: a hand-made valid header announcing MAX_PAYLOAD + 1 bytes, then those bytes."""
    plen = MAX_PAYLOAD + 1
    head = raw_frame(m.MsgType.FRAME_DATA, 0, b"", payload_len=plen)[:HEADER_LEN]
    dec = Decoder()
    assert dec.feed(head) == [] and dec.stats.oversize == 1 and dec.buffered <= 3
    chunk = b"\xa5" * (64 * 1024)
    remaining = plen + TRAILER_LEN
    while remaining > len(chunk):
        assert dec.feed(chunk) == []
        assert dec.buffered <= 3
        remaining -= len(chunk)
    after = m.encode(m.Heartbeat(), 77)
    out = dec.feed(chunk[:remaining] + after)
    assert out == [packet_of(m.Heartbeat(), 77)]
    assert dec.stats.garbage_bytes == HEADER_LEN + plen + TRAILER_LEN - 1 and dec.stats.dropped == 1
    assert_every_byte_accounted(dec, out)


@pytest.mark.parametrize("chunk", [1, 5, 4096])
def test_unsupported_major_version_is_dropped(chunk: int) -> None:
    v2 = raw_frame(0x0001, 3, b"a version 2 payload \x00\x01", major=2)
    after = m.encode(m.Triggered(1, 2), 4)
    dec = Decoder()
    out = feed_chunks(dec, v2 + after, [chunk])
    assert out == [packet_of(m.Triggered(1, 2), 4)]
    s = dec.stats
    assert (s.unsupported_version, s.packets, s.dropped, s.garbage_bytes) == (1, 1, 1, len(v2) - 1)
    assert dec.buffered == 0
    assert_every_byte_accounted(dec, out)


@pytest.mark.parametrize("major, max_payload", [(1, 16), (2, MAX_PAYLOAD)])
def test_frames_inside_a_rejected_frame_are_found_by_the_rescan(major: int, max_payload: int) -> None:
    """SPEC §3: a rejected frame's bytes go back to the magic scan, so a frame carried inside is found."""
    inner = m.encode(m.Time(1), 1)
    outer = raw_frame(m.MsgType.FRAME_DATA, 0, b"head" + inner + b"tail", major=major)
    dec = Decoder(max_payload=max_payload)
    out = dec.feed(outer + m.encode(m.Stop(), 2))
    assert out == [packet_of(m.Time(1), 1), packet_of(m.Stop(), 2)]
    assert dec.stats.dropped == 1 and dec.stats.garbage_bytes == len(outer) - len(inner) - 1


def test_minor_version_and_header_extension_are_accepted() -> None:
    ext = b"\xee" * 12
    wire = raw_frame(m.MsgType.TRIGGERED, 0x1234, m.Triggered(7, 8).pack(), minor=7, header_len=32, ext=ext,
                     flags=FLAG_RESEND)
    dec = Decoder()
    (p,) = dec.feed(wire + m.encode(m.Stop()))[:1]
    assert p == Packet(m.MsgType.TRIGGERED, 0x1234, FLAG_RESEND, m.Triggered(7, 8).pack(), (1, 7))
    assert decode_packet(p) == m.Triggered(7, 8)
    assert dec.stats.packets == 2
    # the payload CRC covers the header extension as well
    bad = bytearray(wire)
    bad[25] ^= 1
    dec = Decoder()
    assert dec.feed(bytes(bad) + m.encode(m.Stop())) == [packet_of(m.Stop())]
    assert dec.stats.payload_crc_errors == 1


@pytest.mark.parametrize("hlen", [0, 19, MAX_HEADER_LEN + 1, 255])
def test_impossible_header_len_is_a_bad_header(hlen: int) -> None:
    bad = struct.pack("<4sBBBBHHIH", MAGIC, 1, 0, hlen, 0, 1, 1, 0, 0)
    bad += header_crc(bad).to_bytes(2, "little") + bytes(8)
    dec = Decoder()
    assert dec.feed(bad + m.encode(m.GetInfo(), 1)) == [packet_of(m.GetInfo(), 1)]
    assert dec.stats.bad_headers == 1 and dec.stats.dropped == 1 and dec.stats.header_crc_errors == 0


def test_max_header_len_and_zero_payload_limit() -> None:
    wire = raw_frame(m.MsgType.TIME, 1, m.Time(5).pack(), header_len=MAX_HEADER_LEN)
    assert Decoder().feed(wire) == [packet_of(m.Time(5), 1)]
    dec = Decoder(max_payload=0)
    assert dec.feed(m.encode(m.Time(5)) + m.encode(m.Heartbeat())) == [packet_of(m.Heartbeat())]
    assert dec.stats.oversize == 1


# -- fuzz: the decoder never raises and stays bounded ------------------------------------------
FUZZ_MAX_PAYLOAD = 256
FUZZ_MAX_FRAME = MAX_HEADER_LEN + FUZZ_MAX_PAYLOAD + TRAILER_LEN


def check_stream_is_harmless(stream: bytes, chunk: int) -> list[Packet]:
    dec = Decoder(max_payload=FUZZ_MAX_PAYLOAD)
    out: list[Packet] = []
    for i in range(0, len(stream), chunk):
        out += dec.feed(stream[i:i + chunk])
        assert dec.buffered <= FUZZ_MAX_FRAME + chunk
        assert dec.buffered < FUZZ_MAX_FRAME  # in fact below one frame once feed() returns
    for p in out:
        assert len(p.payload) <= FUZZ_MAX_PAYLOAD
        try:
            msg = decode_packet(p)
        except ProtocolError:
            continue
        assert type(msg) is m.MESSAGES[p.msg_type]
    s = dec.stats
    assert s.bytes_in == len(stream) and s.packets == len(out)
    assert_every_byte_accounted(dec, out)
    return out


@FUZZ
@given(stream=st.binary(max_size=3000), chunk=st.integers(1, 512))
def test_fuzz_random_bytes(stream, chunk) -> None:
    check_stream_is_harmless(stream, chunk)


mutation = st.one_of(
    st.tuples(st.just("flip"), st.integers(0, 1 << 16), st.integers(0, 7)),
    st.tuples(st.just("insert"), st.integers(0, 1 << 16), st.binary(min_size=1, max_size=30) | st.just(MAGIC)),
    st.tuples(st.just("delete"), st.integers(0, 1 << 16), st.integers(1, 30)),
    st.tuples(st.just("dup"), st.integers(0, 1 << 16), st.integers(1, 80), st.integers(0, 1 << 16)),
)


def mutate(stream: bytes, muts) -> bytes:
    b = bytearray(stream)
    for mut in muts:
        if not b:
            break
        pos = mut[1] % len(b)
        if mut[0] == "flip":
            b[pos] ^= 1 << mut[2]
        elif mut[0] == "insert":
            b[pos:pos] = mut[2]
        elif mut[0] == "delete":
            del b[pos:pos + mut[2]]
        else:
            b[mut[3] % len(b):mut[3] % len(b)] = b[pos:pos + mut[2]]
    return bytes(b)


@FUZZ
@given(items=st.lists(framed, min_size=1, max_size=8), muts=st.lists(mutation, min_size=1, max_size=6),
       chunk=st.integers(1, 200))
def test_fuzz_mutated_valid_streams(items, muts, chunk) -> None:
    stream = mutate(b"".join(encode_all(items)), muts)
    check_stream_is_harmless(stream, chunk)


@FUZZ
@given(mtype=st.sampled_from(sorted(m.MESSAGES)) | u16, payload=st.binary(max_size=200))
def test_fuzz_decode_packet_raises_only_protocol_errors(mtype, payload) -> None:
    try:
        msg = decode_packet(Packet(mtype, 0, 0, payload))
    except UnknownMessageError:
        assert mtype not in m.MESSAGES
        return
    except ProtocolError as exc:
        assert m.MESSAGES[mtype].__name__ in str(exc)
        return
    assert type(msg) is m.MESSAGES[mtype]


@FUZZ
@given(item=framed, muts=st.lists(mutation, min_size=1, max_size=3))
def test_fuzz_mutated_payloads_raise_only_protocol_errors(item, muts) -> None:
    msg = item[0]
    payload = mutate(msg.pack(), muts)
    try:
        out = decode_packet(Packet(msg.TYPE, 0, 0, payload))
    except ProtocolError as exc:
        assert type(msg).__name__ in str(exc)
        return
    assert type(out) is type(msg)


# -- decode_packet on malformed payloads -------------------------------------------------------
SAMPLES: dict[type[m.Message], m.Message] = {
    m.SetConfig: m.SetConfig({1: 640, 10: -5}),
    m.Config: m.Config({}),
    m.ConfigApplied: m.ConfigApplied({3: 30}),
    m.Info: m.Info("STOC", "SN1", "", (1, 1), 1, 2, 3, 4, 5, 6, 0xC0DECAFE),
    m.Triggered: m.Triggered(1, 2),
    m.Status: m.Status(1, True, 0, dict(zip(m.COUNTERS, range(100, 200)))),
    m.Time: m.Time(1),
    m.Nack: m.Nack(3, 4, 8, "bad ✗"),
    m.FrameBegin: m.FrameBegin(*range(14), 0, 1.0, 2.0, 3.0, 0.5),
    m.FrameData: m.FrameData(1, 4, 0, b"abc"),
    m.FrameEnd: m.FrameEnd(1, 0, 2, 3, 4),
    m.CalibRead: m.CalibRead(m.CalibSource.USER, 248, 61440),
    m.CalibData: m.CalibData(m.CalibSource.FACTORY, 3, 0x89ABCDEF, 248, 8, b"\x01\x00\x05\x00data"),
    m.CalibWrite: m.CalibWrite(0, 248, b"\x01\x00\x05\x00body"),
    m.CalibWritten: m.CalibWritten(248),
    m.CalibCommit: m.CalibCommit(m.CalibSource.USER, 248, 0x01234567),
    m.CalibCommitted: m.CalibCommitted(m.CalibSource.USER, 2, 0x76543210),
    m.CalibRestored: m.CalibRestored(m.CalibSource.FACTORY, 1, 0xFEDCBA98),
    m.SetFrameLink: m.SetFrameLink(1024),
    m.FrameLink: m.FrameLink(1024, 8),
    m.FrameResend: m.FrameResend(7, ((4, 1024, 2048),)),
    m.FrameResent: m.FrameResent(7, m.RESEND_SENT, 0, 2),
    m.UpdateBegin: m.UpdateBegin(4096, bytes(range(32)), 1),
    m.UpdateBegun: m.UpdateBegun(1, 0, 4096),
    m.UpdateData: m.UpdateData(256, b"image"),
    m.UpdateWritten: m.UpdateWritten(0, 512, 4096),
    m.UpdateVerified: m.UpdateVerified(m.SlotInfo(1, m.SlotState.STANDBY, 7, bytes(32), "1.2.0")),
    m.UpdateActivating: m.UpdateActivating(m.SlotInfo(1, m.SlotState.PENDING, 7, bytes(32), "1.2.0")),
    m.UpdateConfirmed: m.UpdateConfirmed(m.SlotInfo(1, m.SlotState.ACTIVE, 7, bytes(32), "1.2.0")),
    m.UpdateState: m.UpdateState(0, 0, 0, 0, bytes(32), 3, (m.SlotInfo(0, 1, 3, bytes(32), "1.1.0"),)),
}
FIXED_SIZE = {m.Triggered: 8, m.Time: 8, m.FrameBegin: 56, m.FrameEnd: 17, m.CalibRead: 9, m.CalibWritten: 4,
              m.CalibCommit: 9, m.CalibCommitted: 9, m.CalibRestored: 9, m.SetFrameLink: 4, m.FrameLink: 6,
              m.FrameResend: 14, m.FrameResent: 10, m.UpdateBegin: 37, m.UpdateBegun: 9, m.UpdateWritten: 9}
# messages whose payload ends in data running to the end: the fixed head, then any number of bytes
HEAD_THEN_DATA = {m.FrameData: 9, m.CalibData: 17, m.CalibWrite: 8, m.UpdateData: 4}
EMPTY = [cls for cls in m.MESSAGES.values() if cls not in SAMPLES]


def test_frame_end_carries_the_confidence_count_only_when_that_plane_was_sent() -> None:
    """Since 1.3: a trailing u32 (21 bytes) when the CONFIDENCE plane was sent; 17 bytes read as 0."""
    with_conf = m.FrameEnd(1, 0, 2, 3, 4, 5)
    assert len(with_conf.pack()) == 21 and m.FrameEnd.unpack(with_conf.pack()) == with_conf
    assert m.FrameEnd.unpack(m.FrameEnd(1, 0, 2, 3, 4).pack()).confidence_bytes == 0
    with pytest.raises(ProtocolError, match="FrameEnd"):
        decode_packet(Packet(m.FrameEnd.TYPE, 0, 0, with_conf.pack()[:19]))


def test_samples_cover_every_message_with_a_payload() -> None:
    assert len(EMPTY) == 14 and all(isinstance(cls(), m._Empty) for cls in EMPTY)
    assert m.CalibRestore in EMPTY
    for cls, size in FIXED_SIZE.items():
        assert len(SAMPLES[cls].pack()) == size


@pytest.mark.parametrize("cls", list(SAMPLES), ids=lambda c: c.__name__)
def test_every_truncation_is_a_protocol_error_naming_the_message(cls) -> None:
    payload = SAMPLES[cls].pack()
    assert decode_packet(Packet(cls.TYPE, 0, 0, payload)) == SAMPLES[cls]
    # data running to the end may legitimately be shorter; INFO's trailing fields (1.1, 1.2, 1.3) may be absent
    limit = HEAD_THEN_DATA.get(cls, len(payload) - 6 if cls is m.Info else len(payload))
    for n in range(limit):
        with pytest.raises(ProtocolError, match=cls.__name__) as info:
            decode_packet(Packet(cls.TYPE, 0, 0, payload[:n]))
        assert f"({n} bytes)" in str(info.value)
        assert not isinstance(info.value, UnknownMessageError)


@pytest.mark.parametrize("cls", [*FIXED_SIZE, m.SetConfig, m.Config, m.ConfigApplied], ids=lambda c: c.__name__)
def test_payload_too_long_for_fixed_layout(cls) -> None:
    payload = SAMPLES[cls].pack() + b"\x00"
    with pytest.raises(ProtocolError, match=cls.__name__):
        decode_packet(Packet(cls.TYPE, 0, 0, payload))


@pytest.mark.parametrize("cls", EMPTY, ids=lambda c: c.__name__)
def test_empty_messages_refuse_a_payload(cls) -> None:
    assert decode_packet(Packet(cls.TYPE, 0, 0, b"")) == cls()
    with pytest.raises(ProtocolError, match=f"{cls.__name__} takes no payload, got 1 bytes"):
        decode_packet(Packet(cls.TYPE, 0, 0, b"\x00"))


def test_string_length_running_past_the_end() -> None:
    head = struct.pack("<BBIHHIHH", 1, 0, 0, 0, 0, 0, 0, 0)
    with pytest.raises(ProtocolError, match="Info.*string runs past the payload"):
        decode_packet(Packet(m.MsgType.INFO, 0, 0, head + b"\xc8abc"))
    with pytest.raises(ProtocolError, match="Info"):
        decode_packet(Packet(m.MsgType.INFO, 0, 0, head + b"\x01a\x01b\x05abcd"))
    with pytest.raises(ProtocolError, match="Nack.*string runs past the payload"):
        decode_packet(Packet(m.MsgType.NACK, 0, 0, struct.pack("<HHHH", 3, 4, 0, 0xFFFF) + b"short"))
    # invalid UTF-8 inside a well-formed string is replaced, not an error
    out = decode_packet(Packet(m.MsgType.NACK, 0, 0, struct.pack("<HHHH", 3, 4, 0, 2) + b"\xff\xfe"))
    assert out == m.Nack(3, 4, 0, "\ufffd\ufffd")


def test_counts_that_do_not_match_the_payload() -> None:
    with pytest.raises(ProtocolError, match="Status"):
        decode_packet(Packet(m.MsgType.STATUS, 0, 0, struct.pack("<QBBH", 1, 0, 0, 3) + bytes(16)))
    with pytest.raises(ProtocolError, match="SetConfig.*3 parameters need 20 bytes, got 14"):
        decode_packet(Packet(m.MsgType.SET_CONFIG, 0, 0, struct.pack("<HHiHi", 3, 1, 1, 2, 2)))
    # SPEC §4.2: payload_len MUST be exactly 2 + 6n - also not more whole entries than the count says
    for cls in (m.SetConfig, m.Config, m.ConfigApplied):
        with pytest.raises(ProtocolError, match=f"{cls.__name__}.*1 parameters need 8 bytes, got 14"):
            decode_packet(Packet(cls.TYPE, 0, 0, struct.pack("<HHiHi", 1, 1, 1, 2, 2)))


@pytest.mark.parametrize("mtype", [0x0000, 0x0015, 0x8000, 0x8015, 0x4004, 0x1234, 0xFFFE, 0x0089, 0xC009])
def test_unknown_type(mtype: int) -> None:
    with pytest.raises(UnknownMessageError, match=f"unknown message type 0x{mtype:04x}"):
        decode_packet(Packet(mtype, 0, 0, b""))
    assert issubclass(UnknownMessageError, ProtocolError)


# -- limits ------------------------------------------------------------------------------------
def test_encode_frame_refuses_payloads_over_max_payload() -> None:
    assert len(encode_frame(m.MsgType.FRAME_DATA, 0, bytes(MAX_PAYLOAD))) == MAX_PAYLOAD + 24
    with pytest.raises(ValueError, match=str(MAX_PAYLOAD)):
        encode_frame(m.MsgType.FRAME_DATA, 0, bytes(MAX_PAYLOAD + 1))
    with pytest.raises(ValueError):
        m.encode(m.FrameData(0, 4, 0, bytes(MAX_PAYLOAD - 8)))  # 9-byte FrameData header + data


@pytest.mark.parametrize("bad", [-1, MAX_PAYLOAD + 1, 1 << 32])
def test_decoder_max_payload_out_of_range(bad: int) -> None:
    with pytest.raises(ValueError, match="max_payload"):
        Decoder(max_payload=bad)


@pytest.mark.parametrize("ok", [0, 1, MAX_PAYLOAD])
def test_decoder_max_payload_in_range(ok: int) -> None:
    assert Decoder(max_payload=ok).max_payload == ok


def test_stats_dropped_sums_every_loss_counter() -> None:
    s = DecoderStats(bytes_in=1, packets=2, garbage_bytes=3, header_crc_errors=4, bad_headers=5,
                     payload_crc_errors=6, oversize=7, unsupported_version=8, message_timeouts=9)
    assert s.dropped == 39
    assert s.as_dict()["unsupported_version"] == 8 and "dropped" not in s.as_dict() and len(s.as_dict()) == 9


# -- the parameter table -----------------------------------------------------------------------
def test_param_ids_and_names_are_unique_and_sane() -> None:
    ids = [p.pid for p in PARAMS]
    names = [p.name for p in PARAMS]
    assert len(set(ids)) == len(ids) == 39
    assert ids == [*range(1, 20), *range(21, 41)]  # 1.1 appended 21 and retired 20, 1.2 22..29, 1.3 30..40
    assert len(set(names)) == len(names)
    assert all(1 <= i <= 0xFFFF for i in ids)  # 0 means "no parameter" in a NACK
    assert BY_ID[10].name == "min_disparity" and BY_NAME["width"].pid == 1
    assert all(BY_ID[p.pid] is p and BY_NAME[p.name] is p for p in PARAMS)
    assert all(-(1 << 31) <= p.lo <= p.default <= p.hi < (1 << 31) for p in PARAMS)


def test_each_row_carries_its_description_and_value_names() -> None:
    """One seat per fact: the row is the parameter; names of enumerated values live in it."""
    assert all(p.description for p in PARAMS)
    for p in PARAMS:
        if p.values:  # an enumeration names exactly the values its range allows
            assert sorted(p.values) == list(range(p.lo, p.hi + 1)), p.name
            assert VALUE_NAMES[p.name] is p.values
    assert set(VALUE_NAMES) == {"trigger_mode", "pre_filter_type", "rectify", "algorithm", "trigger_output",
                                "hole_fill"}
    assert VALUE_NAMES["trigger_mode"] == {0: "free_run", 1: "software", 2: "external"}


def test_defaults_pass_their_own_check() -> None:
    d = defaults()
    assert list(d) == [p.name for p in PARAMS]
    assert d["width"] == 640 and d["min_disparity"] == 0 and d["disp12_max_diff"] == -1 and d["outputs"] == 7
    assert all(type(v) is int for v in d.values())
    for p in PARAMS:
        assert p.check(int(p.default)) is None, p
        assert p.check(p.lo) is None and p.check(p.hi) is None, p


@pytest.mark.parametrize("p", PARAMS, ids=lambda p: p.name)
def test_check_rejects_out_of_range(p: Param) -> None:
    for v in (p.lo - 1, p.hi + 1, p.lo - 1000, p.hi + 10**9):
        reason = p.check(v)
        assert reason is not None and p.name in reason and "outside" in reason


def test_check_rejects_even_values_for_odd_params() -> None:
    odd = [p for p in PARAMS if p.odd]
    assert {p.name for p in odd} == {"block_size", "pre_filter_size", "census_width", "census_height",
                                       "median_size"}
    for p in odd:
        for v in range(p.lo, p.hi + 1):
            assert (p.check(v) is None) == (v % 2 == 1), (p.name, v)
        assert "must be odd" in p.check(p.lo + 1)


def test_check_rejects_non_multiples_of_step() -> None:
    stepped = {p.name: p for p in PARAMS if p.step > 1}
    assert {n: p.step for n, p in stepped.items()} == {"width": 16, "height": 8, "num_disparities": 16}
    for p in stepped.values():
        for v in range(p.lo, p.hi + 1):
            assert (p.check(v) is None) == ((v - p.lo) % p.step == 0), (p.name, v)
    assert "multiple of 16" in BY_NAME["width"].check(650)
    assert BY_NAME["height"].check(484) is not None and BY_NAME["height"].check(488) is None
    assert BY_NAME["min_disparity"].check(-256) is None and BY_NAME["min_disparity"].check(-257) is not None


def test_check_accepts_only_the_listed_values_of_a_one_of_parameter() -> None:
    paths = BY_NAME["sgm_paths"]
    assert [v for v in range(paths.lo - 1, paths.hi + 2) if paths.check(v) is None] == [4, 5, 8]
    assert "must be one of 4, 5, 8" in paths.check(6)


def test_v1_1_parameters() -> None:
    """SPEC §5.1: v1.1 added `rectify` (21); id 20 is retired (no simulator control on the wire)."""
    r = BY_NAME["rectify"]
    assert (r.pid, r.default, r.lo, r.hi, r.step, r.odd) == (21, 1, 0, 1, 1, False)
    assert BY_ID[21] is r and PARAMS[19] is r
    assert 20 not in BY_ID and "scene" not in BY_NAME
    assert m.Capability.RAW_OUTPUT == 0x20  # SPEC §4.1 bit 5: the unit implements rectify=0
    assert r.check(0) is None and r.check(1) is None and "outside 0..1" in r.check(2)
    assert defaults()["rectify"] == 1 and list(defaults())[19] == "rectify"


@given(st.integers(-(1 << 31), (1 << 31) - 1))
@example(6)  # inside sgm_paths' range, not one of its values
@settings(max_examples=150, deadline=None)
def test_check_agrees_with_the_table(v: int) -> None:
    for p in PARAMS:
        ok = (p.lo <= v <= p.hi and (not p.odd or v % 2 == 1) and (v - p.lo) % p.step == 0
              and (not p.one_of or v in p.one_of))
        assert (p.check(v) is None) == ok, (p.name, v)
