"""Silent, departed and second hosts never hold or steer the device (issue 9 items 5 and 8).

SPEC §9: a link that delivers no frame for the link timeout is dropped on every transport; a
second TCP client is refused at once with a NACK saying why, and nothing it sent is executed; a pty
host that stops reading cannot block the device, and the next host gets none of the old output.
"""
from __future__ import annotations

import socket
import threading
import time

import pytest
import serial

import stereocam.device_sim.usb as simusb
from stereocam.device_sim import SimulatedCamera
from stereocam.device_sim.clock import FakeClock
from stereocam.device_sim.link_layer.device_link import FIRST_MESSAGE_TIMEOUT_S
from stereocam.device_sim.links.inprocess import InProcessTransport
from stereocam.device_sim.links.servers import PtyServer, TcpServer
from stereocam.protocol import messages as m
from stereocam.protocol.errors import DisconnectedError, ErrorCode
from stereocam.protocol.framing import Decoder
from stereocam.protocol.params import BY_NAME
from stereocam.tools.conformance.budget import budget
from stereocam.transports import open_transport
from tests.support.waiting import wait_until

SMALL = {"width": 320, "height": 240, "num_disparities": 32, "block_size": 11, "fps": 30}


def set_config(rid: int, **values: int) -> bytes:
    return m.encode(m.SetConfig({BY_NAME[k].pid: v for k, v in values.items()}), rid)


class RawTcp:
    """A host that speaks bytes over a real socket."""

    def __init__(self, url: str):
        host, port = url.removeprefix("socket://").rsplit(":", 1)
        self.sock = socket.create_connection((host, int(port)), timeout=5)
        self.decoder = Decoder()

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def messages(self, timeout: float) -> list[m.Message] | None:
        """Messages until ``timeout`` passes quietly; None once the device closed the connection."""
        out: list[m.Message] = []
        self.sock.settimeout(timeout)
        while True:
            try:
                data = self.sock.recv(65536)
            except socket.timeout:
                return out
            except ConnectionResetError:
                return None
            if not data:
                return None if not out else out + [None]
            out += [m.decode_packet(p) for p in self.decoder.feed(data)]

    def wait_closed(self, within: float) -> float:
        """Seconds until the device hung up (fails after ``within``)."""
        t0 = time.monotonic()
        self.sock.settimeout(within)
        try:
            while self.sock.recv(65536):
                pass
        except socket.timeout:
            pytest.fail(f"the device kept a silent connection for more than {within} s")
        except ConnectionResetError:
            pass
        return time.monotonic() - t0

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock()


@pytest.fixture
def tcp(clock):
    sim = SimulatedCamera(seed=91, timebase=clock)  # the link timeouts run on the test's clock
    server = TcpServer(sim)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield server, sim
    server.close()
    thread.join(5)
    sim.close()


def test_a_connection_that_never_speaks_is_dropped(tcp, clock) -> None:
    server, sim = tcp
    silent = RawTcp(server.url)
    wait_until(lambda: sim.attached, what="the server takes the connection")
    clock.advance(FIRST_MESSAGE_TIMEOUT_S - 0.01)
    sim.heartbeat.watchdog()
    assert sim.attached
    clock.advance(0.02)
    silent.wait_closed(within=budget(5))
    host = RawTcp(server.url)  # the slot is free again
    host.send(m.encode(m.GetInfo(), 1))
    assert any(isinstance(x, m.Info) for x in host.messages(1.0) or [])
    host.close()


def test_a_host_that_goes_silent_is_dropped_after_the_link_timeout(tcp, clock) -> None:
    server, sim = tcp
    host = RawTcp(server.url)
    host.send(set_config(1, heartbeat_timeout_ms=300))
    assert isinstance(host.messages(budget(0.2))[0], m.ConfigApplied)
    clock.advance(0.59)  # twice the heartbeat timeout (§9) ...
    sim.heartbeat.watchdog()
    assert sim.attached
    clock.advance(0.02)  # ... and past it
    host.wait_closed(within=budget(5))
    assert not sim.attached


def test_a_second_client_is_refused_and_nothing_it_sent_runs(tcp) -> None:
    server, sim = tcp
    first = RawTcp(server.url)
    first.send(set_config(1, **SMALL))
    assert isinstance(first.messages(0.5)[0], m.ConfigApplied)
    second = RawTcp(server.url)
    second.send(set_config(7, heartbeat_timeout_ms=0) + m.encode(m.Start(), 8))
    told = second.messages(2.0)
    assert told is not None and told[-1] is None, "refused: the device hangs up at once"
    nack = told[0]
    assert isinstance(nack, m.Nack) and nack.code == ErrorCode.BAD_STATE and "another host" in nack.message
    second.close()
    first.send(m.encode(m.Heartbeat(), 2))
    assert isinstance(first.messages(0.5)[0], m.Status)
    first.close()
    wait_until(lambda: not sim.attached, what="the server lets the first host go")
    third = RawTcp(server.url)
    third.send(m.encode(m.GetConfig(), 3))
    cfg = third.messages(1.0)[0]
    assert cfg.values[BY_NAME["heartbeat_timeout_ms"].pid] == 3000
    assert not sim.engine.streaming
    third.close()


def test_an_in_process_link_that_goes_silent_is_dropped() -> None:
    t = InProcessTransport(SimulatedCamera(seed=92))
    try:
        t.write(set_config(1, heartbeat_timeout_ms=200))
        deadline = time.monotonic() + 3
        with pytest.raises(DisconnectedError):
            while time.monotonic() < deadline:
                t.read(65536, 0.1)
        assert not t.sim.attached
    finally:
        t.close()


@pytest.fixture
def pty():
    sim = SimulatedCamera(seed=93)
    server = PtyServer(sim, send_timeout=0.5)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield server, sim
    server.close()
    thread.join(5)
    sim.close()


def test_a_pty_host_that_dies_mid_stream_blocks_nothing_and_leaves_nothing(pty) -> None:
    server, sim = pty
    dead = serial.Serial(server.url, timeout=0.5)
    dead.write(set_config(1, **SMALL, outputs=7, heartbeat_timeout_ms=400) + m.encode(m.Start(), 2))
    deadline = time.monotonic() + 10
    while sim.engine.captured < 1 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert sim.engine.captured >= 1
    # the host stops reading and writing (hung, or died with the pty still open somewhere)
    deadline = time.monotonic() + 5
    while sim.engine.streaming and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not sim.engine.streaming, "the watchdog must stop the stream even while a send is blocked"
    assert sim.counters["heartbeat_timeouts"] + sim.counters["link_send_timeouts"] >= 1
    dead.close()
    wait_until(lambda: not sim.attached, what="the silent host's link is dropped (twice the heartbeat timeout)")
    with serial.Serial(server.url, timeout=0.5) as host:
        host.write(m.encode(m.GetInfo(), 9))
        decoder, got = Decoder(), []
        deadline = time.monotonic() + 5
        while not any(isinstance(x, m.Info) for x in got) and time.monotonic() < deadline:
            got += [m.decode_packet(p) for p in decoder.feed(host.read(65536))]
    stale = [type(x).__name__ for x in got if not isinstance(x, m.Info)]
    assert any(isinstance(x, m.Info) for x in got) and stale == []


def test_a_usb_host_that_went_silent_is_dropped_and_the_next_one_served() -> None:
    sim = SimulatedCamera(seed=94, serial="IDLE-USB")
    device = simusb.plug(sim)
    try:
        with open_transport("usb://?serial=IDLE-USB", timeout=1.0) as t:
            t.write(set_config(1, **SMALL, heartbeat_timeout_ms=200) + m.encode(m.Start(), 2))
            deadline = time.monotonic() + 10
            while sim.engine.captured < 1 and time.monotonic() < deadline:
                time.sleep(0.05)
            deadline = time.monotonic() + 5  # silent and not reading: the stream stops, the link drops
            while (sim.attached or sim.engine.streaming) and time.monotonic() < deadline:
                time.sleep(0.05)
            assert not sim.attached and not sim.engine.streaming
            t.write(m.encode(m.GetInfo(), 3))  # the next host on the wire
            decoder, got = Decoder(), []
            deadline = time.monotonic() + 5
            while not any(isinstance(x, m.Info) for x in got) and time.monotonic() < deadline:
                got += [m.decode_packet(p) for p in decoder.feed(t.read(1 << 20, 0.2))]
        assert [type(x).__name__ for x in got] == ["Info"], "nothing queued for the dropped host is delivered"
    finally:
        device.unplug()
        sim.close()
