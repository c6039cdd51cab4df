"""The link layer under bad links: lost replies, corrupted and split bytes, wrapping request ids."""
from __future__ import annotations

import dataclasses
import struct

import pytest

import stereocam
from stereocam.camera import Camera
from stereocam.protocol import messages as m
from stereocam.protocol.framing import FLAG_RESEND, Decoder

from stereocam.protocol.params import defaults
from stereocam.transports import open_transport
from tests.support.device import SMALL
from tests.support.faults import FaultyTransport, PacketFilter, as_v1_1_info


@pytest.fixture
def faulty(request, device_url):
    """A camera behind a fault-injecting wrapper of its real transport (any device, any link).
    ``{"v1_1": True}``: the host is told (INFO rewritten on the way in) that the device speaks 1.1,
    so it never asks for frame repair; ``{"deliver_incomplete": True}``: flawed frames are delivered."""
    opts = getattr(request, "param", {})
    link = FaultyTransport(open_transport(device_url, 0.5))
    if opts.get("v1_1"):
        link.set_manipulator(read=PacketFilter(as_v1_1_info))
    cam = Camera(link, timeout=0.5, retries=2, deliver_incomplete=opts.get("deliver_incomplete", False))
    cam.configure(**{**defaults(), **SMALL})
    yield cam, link
    cam.close()


def test_lost_reply_is_retried_and_never_applied_twice(faulty, caplog):
    cam, link = faulty
    caplog.set_level("INFO", logger="stereocam.link")
    cam.set_trigger_mode("software")
    cam.start()
    before = cam.status().counters
    dropped = []

    def drop_first_triggered(p):
        if p.msg_type == m.MsgType.TRIGGERED and not dropped:
            dropped.append(p.request_id)
            return b""
        return None

    sent_flags = []
    link.set_manipulator(read=PacketFilter(drop_first_triggered),
                         write=lambda b: sent_flags.append(b[7]) or b)
    trigger_id = cam.trigger()
    assert dropped, "the manipulator never saw the reply"
    assert FLAG_RESEND in sent_flags  # the retry said it was one
    status = cam.status()
    assert status.counters["triggers"] - before["triggers"] == 1  # applied once
    assert status.counters["resends_replayed"] - before["resends_replayed"] == 1
    f = cam.get_frame(timeout=10)
    assert f.trigger_id == trigger_id
    with pytest.raises(stereocam.CameraTimeoutError):
        cam.get_frame(timeout=0.5)  # and exactly one capture came of it
    assert cam.stats["retries"] >= 1
    assert any("Trigger" in r.getMessage() and "resending (try 2 of 3)" in r.getMessage() for r in caplog.records)


def test_request_ids_wrap_and_skip_zero(device_url):
    link = FaultyTransport(open_transport(device_url, 1.0))
    ids = []
    link.set_manipulator(write=lambda b: ids.append(struct.unpack_from("<H", b, 10)[0]) or b)
    from stereocam.link import Link

    lk = Link(link, timeout=1.0, first_request_id=0xFFFE)
    try:
        for _ in range(4):
            assert isinstance(lk.request(m.GetInfo()), m.Info)
    finally:
        lk.close()
    assert ids == [0xFFFE, 0xFFFF, 1, 2]


@pytest.mark.parametrize("faulty", [{"v1_1": True}, {"v1_1": True, "deliver_incomplete": True}],
                         ids=["dropped", "delivered"], indirect=True)
def test_corrupted_frame_is_dropped_and_counted(faulty):
    """Against a 1.1 device (no repair) a damaged chunk costs its capture."""
    cam, link = faulty
    hits = []

    def corrupt_one_chunk(p):
        if p.msg_type == m.MsgType.FRAME_DATA and not hits:
            hits.append(p)
            from stereocam.protocol.framing import encode_frame
            wire = bytearray(encode_frame(p.msg_type, p.request_id, p.payload, p.flags))
            wire[200] ^= 0x40  # a bit error inside the payload
            return bytes(wire)
        return None

    link.set_manipulator(read=PacketFilter(corrupt_one_chunk))
    cam.configure(fps=10)
    cam.start()
    frames = [cam.get_frame(timeout=10) for _ in range(3)]
    cam.stop()
    st = cam.stats
    assert st["payload_crc_errors"] == 1
    assert st["incomplete"] == 1  # the capture that lost its chunk never reached the user
    assert hits[0].payload[:4] != b""
    bad_seq = struct.unpack_from("<I", hits[0].payload)[0]
    by_seq = {f.sequence: f for f in frames}
    if cam.connection.assembler.deliver_incomplete:  # handed out, but marked, and the gap reads as zeros
        assert by_seq[bad_seq].status is stereocam.FrameStatus.MISSING_DATA
        assert all(f.status is stereocam.FrameStatus.COMPLETE for s, f in by_seq.items() if s != bad_seq)
    else:
        assert bad_seq not in by_seq
        assert all(f.status is stereocam.FrameStatus.COMPLETE for f in frames)


def test_bytes_split_into_tiny_reads(faulty):
    cam, link = faulty
    link.max_read = 7
    cam.set_trigger_mode("software")
    cam.start()
    cam.trigger()
    f = cam.get_frame(timeout=30)
    assert f.left.shape == (240, 320)
    assert cam.stats["garbage_bytes"] == 0 and cam.stats["frames"] == 1


def test_garbage_injected_into_the_read_stream(faulty):
    cam, link = faulty
    n = [0]

    def noisy(b):
        n[0] += 1
        return (b"\x00STOC\xff" * 3 + b) if n[0] % 3 == 0 else b

    link.set_manipulator(read=noisy)
    for _ in range(20):
        assert cam.config()["width"] == 320
    assert cam.stats["garbage_bytes"] > 0


def test_version_mismatch_is_refused(device_url):
    link = FaultyTransport(open_transport(device_url, 1.0))

    def as_version_2(p):
        if p.msg_type != m.MsgType.INFO:
            return None
        return m.encode(dataclasses.replace(m.decode_packet(p), protocol_version=(2, 0)), p.request_id)

    link.set_manipulator(read=PacketFilter(as_version_2))
    with pytest.raises(stereocam.VersionMismatchError, match="protocol 2.0"):
        Camera(link)


def test_decoder_used_by_host_and_device_is_the_same_codec():
    # one codec: what the device encodes, the host decodes, byte for byte
    wire = m.encode(m.Triggered(5, 9), 77)
    (p,) = Decoder().feed(wire)
    assert m.decode_packet(p) == m.Triggered(5, 9) and p.request_id == 77
