"""The Transport contract, held against every transport (in-process, pty, TCP, USB) or ``--device``.

Like python-can's back-to-back interface tests: the link layer is written once, so every
transport must behave the same at its edges — timeouts, fragments, close, and a write that
times out (the device is busy, not gone), which must cost one try and never the link.
"""
from __future__ import annotations

import time

import pytest

import stereocam
from stereocam.camera import Camera
from stereocam.link import Link
from stereocam.protocol import messages as m
from stereocam.protocol.framing import Decoder
from stereocam.tools.conformance.budget import budget
from stereocam.transports import open_transport
from tests.support.faults import FaultyTransport


def _reply(transport, request: m.Message, rid: int, timeout: float = 3.0) -> m.Message:
    """Send one request as raw bytes and read until its reply decodes (other traffic skipped)."""
    transport.write(m.encode(request, rid))
    decoder = Decoder()
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for packet in decoder.feed(transport.read(1 << 16, 0.1)):
            if packet.request_id == rid and packet.msg_type & m.REPLY_BIT:
                return m.decode_packet(packet)
    raise AssertionError(f"no reply to {type(request).__name__} within {timeout} s")


@pytest.fixture
def transport(device_url):
    t = open_transport(device_url, 1.0)
    yield t
    t.close()


def test_read_with_nothing_to_read_returns_empty_after_the_timeout(transport):
    _reply(transport, m.Stop(), 1)  # a quiet device: no stream
    while transport.read(1 << 16, 0.2):
        pass  # drain anything still in flight
    t0 = time.monotonic()
    assert transport.read(1 << 16, 0.3) == b""
    waited = time.monotonic() - t0
    assert 0.2 <= waited < 1.5


def test_request_and_reply_as_raw_bytes(transport):
    info = _reply(transport, m.GetInfo(), 7)
    assert isinstance(info, m.Info) and info.serial


def test_a_request_written_one_byte_at_a_time_is_answered(transport):
    wire = m.encode(m.GetConfig(), 9)
    for i in range(len(wire)):
        transport.write(wire[i:i + 1])
    decoder = Decoder()
    deadline = time.monotonic() + budget(3)
    replies = []
    while not replies and time.monotonic() < deadline:
        replies = [p for p in decoder.feed(transport.read(1 << 16, 0.1)) if p.request_id == 9]
    assert replies and isinstance(m.decode_packet(replies[0]), m.Config)


def test_close_is_idempotent_and_io_after_close_is_a_typed_error(transport):
    transport.close()
    transport.close()
    with pytest.raises(stereocam.StereoCamError):
        transport.write(m.encode(m.GetInfo(), 1))
    with pytest.raises(stereocam.StereoCamError):
        transport.read(16, 0.1)


def test_a_write_that_times_out_costs_one_try_not_the_link(device_url):
    """A busy device that does not take bytes in time is not a lost device."""
    faulty = FaultyTransport(open_transport(device_url, 1.0))
    stalls = [2]

    def stall(data: bytes) -> bytes:
        if stalls[0]:
            stalls[0] -= 1
            raise stereocam.CameraTimeoutError("device accepted 0 bytes in time")
        return data

    link = Link(faulty, timeout=1.0, retries=2)
    try:
        faulty.set_manipulator(write=stall)
        assert isinstance(link.request(m.GetInfo()), m.Info)  # third try goes through
        assert link.alive and link.error is None
        assert link.stats.retries == 2
        stalls[0] = 3
        with pytest.raises(stereocam.CameraTimeoutError):
            link.request(m.GetInfo())  # every try stalled: a timeout, still not a dead link
        assert link.alive
        assert isinstance(link.request(m.GetInfo()), m.Info)
    finally:
        link.close()


def test_a_camera_rides_through_write_stalls(device_url):
    faulty = FaultyTransport(open_transport(device_url, 1.0))
    cam = Camera(faulty, timeout=1.0, retries=2)
    try:
        stalled = []

        def stall_once(data: bytes) -> bytes:
            if not stalled:
                stalled.append(1)
                raise stereocam.CameraTimeoutError("stalled")
            return data

        faulty.set_manipulator(write=stall_once)
        assert cam.config()["width"] > 0
        assert stalled and cam.alive
    finally:
        cam.close()
