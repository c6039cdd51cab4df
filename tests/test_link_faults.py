"""The link layer under bad links: lost replies, corrupted and split bytes, wrapping request ids."""
from __future__ import annotations

import struct

import pytest

import stereocam
from stereocam.device_sim import SimulatedCamera
from stereocam.camera import Camera
from stereocam.device_sim.links.inprocess import InProcessTransport
from stereocam.protocol import messages as m
from stereocam.protocol.framing import FLAG_RESEND, Decoder

from .faults import FaultyTransport, PacketFilter


def as_v1_1_device(sim: SimulatedCamera) -> None:
    """Make ``sim`` answer like a protocol 1.1 device: no FRAME_REPAIR capability, no 1.2 requests."""
    real = sim._get_info
    sim._handlers[m.MsgType.GET_INFO] = lambda msg: m.Info(**{
        **real(msg).__dict__, "protocol_version": (1, 1),
        "capabilities": real(msg).capabilities & ~m.Capability.FRAME_REPAIR})
    del sim._handlers[m.MsgType.SET_FRAME_LINK], sim._handlers[m.MsgType.FRAME_RESEND]


@pytest.fixture
def faulty(request):
    opts = getattr(request, "param", {})
    sim = SimulatedCamera(seed=11)
    if opts.get("v1_1"):
        as_v1_1_device(sim)
    link = FaultyTransport(InProcessTransport(sim))
    cam = Camera(link, timeout=0.5, retries=2, deliver_incomplete=opts.get("deliver_incomplete", False))
    cam.configure(width=320, height=240, num_disparities=32, block_size=11)
    yield cam, link, sim
    cam.close()


def test_lost_reply_is_retried_and_never_applied_twice(faulty):
    cam, link, sim = faulty
    cam.set_trigger_mode("software")
    cam.start()
    dropped = []

    def drop_first_triggered(p):
        if p.msg_type == m.MsgType.TRIGGERED and not dropped:
            dropped.append(p.request_id)
            return b""
        return None

    sent_flags = []
    link.set_manipulator(read=PacketFilter(drop_first_triggered),
                         write=lambda b: sent_flags.append(b[7]) or b)
    assert cam.trigger() == 1
    assert dropped, "the manipulator never saw the reply"
    assert FLAG_RESEND in sent_flags  # the retry said it was one
    status = cam.status()
    assert status.counters["triggers"] == 1  # applied once
    assert status.counters["resends_replayed"] == 1
    f = cam.get_frame(timeout=10)
    assert f.trigger_id == 1
    with pytest.raises(stereocam.CameraTimeoutError):
        cam.get_frame(timeout=0.5)  # and exactly one capture came of it
    assert cam.stats["retries"] >= 1


def test_request_ids_wrap_and_skip_zero():
    sim = SimulatedCamera(seed=12)
    link = FaultyTransport(InProcessTransport(sim))
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
    cam, link, sim = faulty
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
    if cam.assembler.deliver_incomplete:  # handed out, but marked, and the gap reads as zeros
        assert by_seq[bad_seq].status is stereocam.FrameStatus.MISSING_DATA
        assert all(f.status is stereocam.FrameStatus.COMPLETE for s, f in by_seq.items() if s != bad_seq)
    else:
        assert bad_seq not in by_seq
        assert all(f.status is stereocam.FrameStatus.COMPLETE for f in frames)


def test_bytes_split_into_tiny_reads(faulty):
    cam, link, sim = faulty
    link.max_read = 7
    cam.set_trigger_mode("software")
    cam.start()
    cam.trigger()
    f = cam.get_frame(timeout=30)
    assert f.left.shape == (240, 320)
    assert cam.stats["garbage_bytes"] == 0 and cam.stats["frames"] == 1


def test_garbage_injected_into_the_read_stream(faulty):
    cam, link, sim = faulty
    n = [0]

    def noisy(b):
        n[0] += 1
        return (b"\x00STOC\xff" * 3 + b) if n[0] % 3 == 0 else b

    link.set_manipulator(read=noisy)
    for _ in range(20):
        assert cam.config()["width"] == 320
    assert cam.stats["garbage_bytes"] > 0


def test_version_mismatch_is_refused():
    sim = SimulatedCamera(seed=13)
    real = sim._get_info
    sim._handlers[m.MsgType.GET_INFO] = lambda msg: m.Info(**{**real(msg).__dict__, "protocol_version": (2, 0)})
    with pytest.raises(stereocam.VersionMismatchError, match="protocol 2.0"):
        Camera(InProcessTransport(sim))


def test_decoder_used_by_host_and_device_is_the_same_codec():
    # one codec: what the device encodes, the host decodes, byte for byte
    wire = m.encode(m.Triggered(5, 9), 77)
    (p,) = Decoder().feed(wire)
    assert m.decode_packet(p) == m.Triggered(5, 9) and p.request_id == 77
