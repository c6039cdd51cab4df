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
from stereocam.device_sim.links.servers import WAIT_FOR_SLOT_S, PtyServer, TcpServer
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


def _serving(server, sim: SimulatedCamera):
    """A fixture's body: ``server`` serving ``sim`` on a thread until the test ends."""
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield server, sim
    server.close()
    thread.join(5)
    sim.close()


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock()


@pytest.fixture
def tcp(clock):
    sim = SimulatedCamera(seed=91, timebase=clock)  # the link timeouts run on the test's clock
    yield from _serving(TcpServer(sim), sim)


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
    told = second.messages(5.0)
    assert told is not None and told[-1] is None, "refused: the device hangs up once the wait for the slot is over"
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
        deadline = time.monotonic() + budget(3)  # dropped after 0.4 s of silence; stretched on a busy host
        with pytest.raises(DisconnectedError):
            while time.monotonic() < deadline:
                t.read(65536, 0.1)
        assert not t.sim.attached
    finally:
        t.close()


@pytest.fixture
def pty():
    sim = SimulatedCamera(seed=93)
    yield from _serving(PtyServer(sim, send_timeout=0.5), sim)


def test_a_pty_host_that_dies_mid_stream_blocks_nothing_and_leaves_nothing(pty) -> None:
    server, sim = pty
    dead = serial.Serial(server.url, timeout=0.5)
    # a watchdog long enough that a loaded machine captures before it fires
    dead.write(set_config(1, **SMALL, outputs=7, heartbeat_timeout_ms=1500) + m.encode(m.Start(), 2))
    wait_until(lambda: sim.engine.captured >= 1, 10, "a capture")
    # the host stops reading and writing (hung, or died with the pty still open somewhere)
    wait_until(lambda: not sim.engine.streaming, 10, "the watchdog must stop the stream even while a send is blocked")
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
            wait_until(lambda: sim.engine.captured >= 1, 10, "a capture")
            # silent and not reading: the stream stops, the link drops
            wait_until(lambda: not sim.attached and not sim.engine.streaming, 5, "the silent host dropped")
            t.write(m.encode(m.GetInfo(), 3))  # the next host on the wire
            decoder, got = Decoder(), []
            deadline = time.monotonic() + 5
            while not any(isinstance(x, m.Info) for x in got) and time.monotonic() < deadline:
                got += [m.decode_packet(p) for p in decoder.feed(t.read(1 << 20, 0.2))]
        assert [type(x).__name__ for x in got] == ["Info"], "nothing queued for the dropped host is delivered"
    finally:
        device.unplug()
        sim.close()


def test_a_silent_host_with_the_watchdog_off_yields_the_tcp_slot_to_the_next_host(tcp, clock) -> None:
    """Issue 22.6: a client that sets heartbeat_timeout_ms=0 and goes silent keeps no one out for
    long: once it has been silent for the default link timeout (2 x 3 s on the unit's clock), the
    next host that connects gets the device (it used to be refused forever)."""
    server, sim = tcp
    squatter = RawTcp(server.url)
    squatter.send(set_config(1, heartbeat_timeout_ms=0))
    assert isinstance(squatter.messages(0.3)[0], m.ConfigApplied)
    clock.advance(5.5)  # silent, but not yet for the default link timeout: the next host is refused
    host = RawTcp(server.url)
    host.send(m.encode(m.GetInfo(), 2))
    got = host.messages(3.0) or []
    assert got and isinstance(got[0], m.Nack) and "busy" in got[0].message, got
    host.close()
    clock.advance(1.0)  # now past it: the next host that knocks gets the unit
    host = RawTcp(server.url)
    host.send(m.encode(m.GetInfo(), 2))
    got: list[m.Message] = []

    def served() -> bool:
        got.extend(host.messages(0.2) or [])
        return any(isinstance(x, m.Info) for x in got)
    wait_until(served, what="the next host served")
    assert squatter.messages(0.5) is None  # the silent host was hung up on
    host.close()


@pytest.fixture
def default_pty():
    sim = SimulatedCamera(seed=94)
    yield from _serving(PtyServer(sim), sim)  # the default send timeout (5 s): longer than the watchdog's


def test_the_next_pty_host_after_one_killed_mid_stream_gets_no_stale_output_and_a_prompt_answer(default_pty) -> None:
    """Issue 22.17: a streaming pty host dies (its port closed, no STOP, the watchdog at its default
    3 s); the next host, opening at once, is answered within a second and reads nothing of the old
    stream."""
    server, sim = default_pty
    dead = serial.Serial(server.url, timeout=0.5)
    dead.write(set_config(1, **SMALL, outputs=7) + m.encode(m.Start(), 2))
    decoder, ends = Decoder(), 0
    deadline = time.monotonic() + 10
    while ends < 2 and time.monotonic() < deadline:  # a host reading its stream
        ends += sum(p.msg_type == m.MsgType.FRAME_END for p in decoder.feed(dead.read(65536)))
    assert ends >= 2 and sim.engine.streaming
    dead.close()  # killed: the port closes with the stream running
    wait_until(lambda: not sim.engine.streaming, 2, "the device must notice that no host holds the pty")
    with serial.Serial(server.url, timeout=0.2) as host:
        sent = time.monotonic()
        host.write(m.encode(m.GetInfo(), 9))
        decoder, got = Decoder(), []
        while not any(isinstance(x, m.Info) for x in got) and time.monotonic() - sent < 5:
            got += [m.decode_packet(p) for p in decoder.feed(host.read(65536))]
        answered = time.monotonic() - sent
    assert [type(x).__name__ for x in got] == ["Info"] and answered < 1.0, (answered, len(got))


def test_a_host_that_sent_a_lot_and_closed_does_not_keep_the_next_one_out(tcp) -> None:
    """Issue 22.17: a client writes 1.4 MB and closes; a host connecting right after is served as
    soon as the device has worked through those bytes, not refused 'busy' meanwhile."""
    import random

    server, sim = tcp
    noise = random.Random(17).randbytes(1_400_000)
    for attempt in range(3):
        gone = RawTcp(server.url)
        gone.send(noise)
        gone.close()
        host = RawTcp(server.url)
        sent = time.monotonic()
        host.send(m.encode(m.GetInfo(), 1))
        host.sock.settimeout(3.0)
        got: list[m.Message] = []
        while not got:  # the first answer, timed (a socket timeout here fails the test)
            data = host.sock.recv(65536)
            assert data, f"attempt {attempt}: the device hung up on the next host"
            got += [m.decode_packet(p) for p in host.decoder.feed(data)]
        assert isinstance(got[0], m.Info), (attempt, got[:1])
        assert time.monotonic() - sent < WAIT_FOR_SLOT_S
        host.close()
        wait_until(lambda: not sim.attached, 5, f"attempt {attempt}: the closed host detached")


def test_the_sdk_says_the_device_is_busy_when_another_host_holds_it(tcp) -> None:
    """Issue 22.17: refused because another host holds the device, the SDK's error carries the
    device's reason ('busy: another host ...'), not a bare 'socket disconnected'."""
    import stereocam

    server, _ = tcp
    holder = RawTcp(server.url)
    holder.send(m.encode(m.Heartbeat(), 1))
    assert isinstance(holder.messages(0.3)[0], m.Status)
    with pytest.raises(stereocam.TransportError, match="busy: another host"):
        stereocam.open(server.url, timeout=1.0)
    holder.close()
