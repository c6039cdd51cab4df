"""Device-mode calibration sends nothing but protocol parameters (SPEC §5): proven on real sockets.

A recording TCP proxy sits between the ``stereocam calibrate`` CLI and a simulator served in its
own process showing its board (``--scene board``); it decodes every host→device frame and keeps
the parameter ids of each SET_CONFIG. A parameter the protocol table does not list fails the test,
and the device itself refuses such an id with UNKNOWN_PARAM.
"""
from __future__ import annotations

import select
import socket
import subprocess
import sys
import threading
from dataclasses import dataclass, field

import pytest

import stereocam
from stereocam.camera import Camera
from stereocam.device_sim import SimulatedCamera
from stereocam.device_sim.links.inprocess import InProcessTransport
from stereocam.device_sim.process import ServedSimulator
from stereocam.device_sim.rig.sensor import BOARD
from stereocam.protocol import messages as m
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.framing import Decoder, encode_frame
from stereocam.protocol.params import BY_NAME, PARAMS
from stereocam.tools.calibration.solve import SolveConfig
from stereocam.tools.calibration.device import EXIT_UNSUPPORTED, calibrate_device

from tests.support.faults import FaultyTransport, PacketFilter


@dataclass
class WireLog:
    set_config_ids: list[int] = field(default_factory=list)  # every id of every host SET_CONFIG
    request_types: set[int] = field(default_factory=set)

    @property
    def foreign_ids(self) -> list[int]:
        known = {p.pid for p in PARAMS}
        return [pid for pid in self.set_config_ids if pid not in known]


class RecordingProxy:
    """Forwards one TCP connection at a time to ``upstream``, decoding what the host sends."""

    def __init__(self, upstream_url: str):
        host, _, port = upstream_url.removeprefix("socket://").rpartition(":")
        self._upstream = (host, int(port))
        self._listener = socket.create_server(("127.0.0.1", 0))
        self._listener.settimeout(0.1)
        self.url = "socket://127.0.0.1:%d" % self._listener.getsockname()[1]
        self.log = WireLog()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._accept_loop, name="proxy", daemon=True)
        self._thread.start()

    def _accept_loop(self) -> None:
        while not self._stop.is_set():
            try:
                host_side, _ = self._listener.accept()
            except (socket.timeout, OSError):
                continue
            try:
                with host_side, socket.create_connection(self._upstream) as device_side:
                    self._pump(host_side, device_side)
            except OSError:  # either end went away: wait for the next host
                continue

    def _pump(self, host_side: socket.socket, device_side: socket.socket) -> None:
        decoder = Decoder()
        while not self._stop.is_set():
            ready, _, _ = select.select([host_side, device_side], [], [], 0.1)
            for sock in ready:
                data = sock.recv(65536)
                if not data:
                    return
                if sock is host_side:
                    self._record(decoder.feed(data))
                    device_side.sendall(data)
                else:
                    host_side.sendall(data)

    def _record(self, packets) -> None:
        for p in packets:
            self.log.request_types.add(p.msg_type)
            if p.msg_type == m.MsgType.SET_CONFIG:
                self.log.set_config_ids += list(m.decode_packet(p).values)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self._listener.close()


@pytest.fixture
def board_over_proxy():
    with ServedSimulator("tcp:127.0.0.1:0", seed=75, scene="board") as served:
        proxy = RecordingProxy(served.url)
        try:
            yield proxy
        finally:
            proxy.close()


def test_device_mode_calibration_sends_only_protocol_parameters(board_over_proxy, tmp_path):
    proxy = board_over_proxy
    r = subprocess.run([sys.executable, "-m", "stereocam.tools.cli", "calibrate", proxy.url, "--out", str(tmp_path),
                        "--size", "640x480", "--max-views", "15", "-q"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "PASSED" in r.stdout and "verified by read-back" in r.stdout
    assert m.MsgType.CALIB_COMMIT in proxy.log.request_types  # the whole run went through the proxy
    assert BY_NAME["rectify"].pid in proxy.log.set_config_ids
    assert proxy.log.foreign_ids == [], f"simulator-only parameters crossed the wire: {proxy.log.foreign_ids}"

    with stereocam.open(proxy.url, timeout=2.0) as cam:  # the device refuses an id the table lacks
        with pytest.raises(stereocam.DeviceError) as err:
            cam.request(m.SetConfig({20: 2}))
        assert err.value.code == ErrorCode.UNKNOWN_PARAM
        assert "scene" not in cam.config()
    assert proxy.log.foreign_ids == [20]  # and the proxy sees such an id when one is sent


def test_calibration_needs_raw_output_advertised(tmp_path):
    """A unit without INFO capability RAW_OUTPUT is not switched to raw or written to."""
    sim = SimulatedCamera(seed=76, flash_path=tmp_path / "n.flash", factory_calibrated=False, scene="board")
    link = FaultyTransport(InProcessTransport(sim))

    def no_raw(p):
        if p.msg_type != m.MsgType.INFO:
            return None
        info = m.decode_packet(p)
        return encode_frame(p.msg_type, p.request_id,
                            m.Info(**{**info.__dict__, "capabilities": info.capabilities & ~m.Capability.RAW_OUTPUT}
                                   ).pack(), p.flags)

    link.set_manipulator(read=PacketFilter(no_raw))
    with Camera(link, timeout=2.0) as cam:
        before = cam.config()
        code, result, verdict = calibrate_device(cam, BOARD, SolveConfig(), tmp_path, size=(640, 480))
        assert code == EXIT_UNSUPPORTED and result is None and "RAW_OUTPUT" in verdict
        assert cam.config() == before and cam.read_calibration() is None
