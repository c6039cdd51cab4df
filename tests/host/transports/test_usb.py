"""stereocam.transports.usb and host.discovery over the simulated bus, plus the real libusb backend."""
from __future__ import annotations

import threading
import time

import pytest
import usb.core

import stereocam.device_sim.usb as simusb
from stereocam.device_sim.usb.testdevices import EchoDevice, SourceDevice
from stereocam.discovery import DeviceEntry, list_devices
from stereocam.transports import open_transport
from stereocam.transports import usb as usbt
from stereocam.protocol.errors import DisconnectedError, StereoCamError, TransportError
from stereocam.tools.conformance.budget import budget
from tests.support.waiting import wait_until


pytestmark = pytest.mark.sim_only("drives the simulated USB bus")


@pytest.fixture
def echo():
    echo = EchoDevice(serial="ECHO-T1")
    simusb.plug(echo)
    return echo


def read_exactly(t, n: int, timeout: float = 2.0) -> bytes:
    got = bytearray()
    deadline = time.monotonic() + timeout
    while len(got) < n and time.monotonic() < deadline:
        got += t.read(n - len(got), 0.2)
    return bytes(got)


@pytest.mark.parametrize("url,ids,serial", [
    ("usb://", usbt.CAMERA_IDS, None),
    ("usb://1209:0001", ((0x1209, 0x0001),), None),
    ("usb://?serial=SN1", usbt.CAMERA_IDS, "SN1"),
    ("usb://abcd:ef01/?serial=X", ((0xABCD, 0xEF01),), "X"),
])
def test_parse_url(url, ids, serial):
    assert usbt.parse_url(url) == usbt.UsbSelector(ids, serial)


@pytest.mark.parametrize("url", ["usb://12:zz", "usb://1209", "usb://?port=3", "serial://x"])
def test_parse_url_rejects(url):
    with pytest.raises(ValueError):
        usbt.parse_url(url)


def test_camera_ids_agree_with_the_simulated_descriptors():
    assert usbt.CAMERA_IDS[0] == (simusb.VENDOR_ID, simusb.PRODUCT_ID)
    assert usbt.MAX_PACKET_SIZE == simusb.MAX_PACKET_SIZE and usbt.READ_SIZE % 512 == 0


def test_roundtrip_through_the_scheme_registry(echo):
    with open_transport("usb://", timeout=1.0) as t:
        assert isinstance(t, usbt.UsbTransport) and t.url == "usb://"
        t.write(b"ping")
        assert t.read(4096, 1.0) == b"ping"
        start = time.monotonic()
        assert t.read(4096, 0.1) == b""  # timeout: empty, not an error
        assert 0.09 <= time.monotonic() - start < budget(0.6)


def test_select_by_serial_and_vid_pid():
    for serial in ("A1", "B2"):
        simusb.plug(EchoDevice(serial=serial))
    with open_transport("usb://?serial=B2") as t:
        t.write(b"x")
        assert t.read(10, 1.0) == b"x"
        assert t.device.serial_number == "B2"
    with open_transport("usb://1209:0001?serial=A1") as t:
        assert t.device.serial_number == "A1"
    with pytest.raises(TransportError, match="no USB camera"):
        open_transport("usb://?serial=NOPE")
    with pytest.raises(TransportError, match="dead:beef"):
        open_transport("usb://dead:beef")


def test_camera_in_use_then_free_after_close(echo):
    first = open_transport("usb://?serial=ECHO-T1")
    with pytest.raises(TransportError, match="in use"):
        open_transport("usb://?serial=ECHO-T1")
    first.close()
    first.close()  # idempotent
    with open_transport("usb://?serial=ECHO-T1") as again:
        again.write(b"ok")
        assert again.read(10, 1.0) == b"ok"


def test_read_returns_at_most_max_bytes_and_keeps_the_rest(echo):
    with open_transport("usb://") as t:
        t.write(b"0123456789")
        assert t.read(4, 1.0) == b"0123"
        assert t.read(100, 0.0) == b"456789"


def test_large_stream_arrives_intact():
    total, chunk = 8 * 1024 * 1024, 640 * 480 * 2
    simusb.plug(SourceDevice(serial="SRC", chunk=chunk))
    with open_transport("usb://?serial=SRC") as t:
        t.write(str(total).encode())
        data = read_exactly(t, total, timeout=20)
    pattern = (bytes(range(256)) * (chunk // 256 + 1))[:chunk]
    assert len(data) == total
    assert data == (pattern * (total // chunk + 1))[:total - total % chunk] + pattern[:total % chunk]


def test_zero_length_packet_is_not_taken_for_a_timeout(echo):
    with open_transport("usb://") as t:
        echo.send(b"p" * usbt.READ_SIZE)  # fills one read exactly; its ZLP is left queued
        assert read_exactly(t, usbt.READ_SIZE) == b"p" * usbt.READ_SIZE
        timer = threading.Timer(0.2, echo.send, args=(b"later",))
        timer.start()
        start = time.monotonic()
        assert t.read(4096, 2.0) == b"later"  # the lone ZLP did not end the wait
        assert time.monotonic() - start >= 0.15
        timer.join()


def test_stalled_endpoint_is_cleared_and_read_retried(echo):
    with open_transport("usb://") as t:
        simusb.plugged_devices()[0].halt(simusb.EP_IN)
        echo.send(b"after stall")
        assert t.read(100, 1.0) == b"after stall"


def test_unplug_mid_read_raises_disconnected_within_the_timeout(echo):
    device = simusb.plugged_devices()[0]
    t = open_transport("usb://")
    errors: list[BaseException] = []

    def reader() -> None:
        try:
            while True:
                t.read(4096, 5.0)
        except StereoCamError as exc:
            errors.append(exc)

    thread = threading.Thread(target=reader)
    thread.start()
    wait_until(lambda: device.in_pipe.waiting, what="the read waits for data")
    start = time.monotonic()
    device.unplug()
    thread.join(5.0)
    assert not thread.is_alive(), "read hung after unplug"
    assert time.monotonic() - start < budget(1.0)
    assert isinstance(errors[0], DisconnectedError)
    with pytest.raises(DisconnectedError):
        t.read(10, 0.1)
    with pytest.raises(DisconnectedError):
        t.write(b"x")
    t.close()


def test_close_from_another_thread_ends_a_pending_read(echo):
    t = open_transport("usb://")
    errors: list[BaseException] = []

    def reader() -> None:
        try:
            t.read(4096, 10.0)
        except StereoCamError as exc:
            errors.append(exc)

    thread = threading.Thread(target=reader)
    thread.start()
    wait_until(lambda: simusb.plugged_devices()[0].in_pipe.waiting, what="the read waits for data")
    start = time.monotonic()
    t.close()
    thread.join(3.0)
    assert not thread.is_alive() and time.monotonic() - start < budget(1.0)
    assert isinstance(errors[0], DisconnectedError)


def test_list_devices_finds_plugged_simulators():
    handles = [simusb.plug(EchoDevice(serial=s)) for s in ("L1", "L2")]
    entries = [e for e in list_devices() if e.transport == "usb"]
    assert [(e.serial, e.model, e.transport, e.firmware) for e in entries] == [
        ("L1", "Echo", "usb", "1.2.3"), ("L2", "Echo", "usb", "1.2.3")]
    assert all(isinstance(e, DeviceEntry) for e in entries)
    with open_transport(entries[1].url) as t:  # the listed URL opens that very camera
        assert t.device.serial_number == "L2"
    handles[0].unplug()
    assert [e.serial for e in list_devices() if e.transport == "usb"] == ["L2"]


def test_list_devices_includes_free_in_process_simulators():
    from stereocam.device_sim import SimulatedCamera
    import stereocam

    sim = SimulatedCamera(serial="INPROC-9", seed=9)
    try:
        (entry,) = [e for e in list_devices() if e.serial == "INPROC-9"]
        assert (entry.transport, entry.url, entry.model) == ("sim", "sim://?serial=INPROC-9", "STOC-SIM")
        with stereocam.open(entry.url) as cam:  # that very simulator, not a fresh one
            assert cam.info().serial == "INPROC-9" and sim.attached
            assert "INPROC-9" not in [e.serial for e in list_devices()]  # held by a link now
        assert not sim.attached
    finally:
        sim.close()
    assert "INPROC-9" not in [e.serial for e in list_devices()]


def test_list_devices_table(capsys):
    from stereocam.tools.camera.list_devices import main
    simusb.plug(EchoDevice(serial="TBL1"))
    assert main([]) == 0
    out = capsys.readouterr().out
    assert "usb://?serial=TBL1" in out and "usb (sim)" in out


def test_real_libusb_backend_loads_and_enumerates():
    import libusb_package

    backend = libusb_package.get_libusb1_backend()
    assert backend is not None, "libusb-package's libusb-1.0 did not load"
    assert usbt.real_backend() is not None
    devices = list(usb.core.find(find_all=True, backend=backend))  # none is a valid answer
    assert all(isinstance(d, usb.core.Device) for d in devices)


def test_simulated_camera_over_usb_answers_get_info():
    from stereocam.device_sim import SimulatedCamera
    from stereocam.link import Link
    from stereocam.protocol import messages as m

    cam = SimulatedCamera(serial="USBCAM1", seed=3)
    simusb.plug(cam)
    link = Link(open_transport("usb://?serial=USBCAM1", timeout=1.0), timeout=2.0)
    try:
        info = link.request(m.GetInfo())
        assert info.serial == "USBCAM1"
    finally:
        link.close()
        cam.close()


def test_unplug_while_streaming_surfaces_disconnect_in_the_sdk():
    import stereocam
    from stereocam.device_sim import SimulatedCamera

    cam = SimulatedCamera(serial="USBCAM2", seed=4)
    device = simusb.plug(cam)
    try:
        with stereocam.open("usb://?serial=USBCAM2", timeout=2.0) as camera:
            camera.configure(width=320, height=240, fps=30)
            camera.start()
            frame = camera.get_frame(timeout=30.0)  # the first one may wait for JIT compiling
            assert frame.left is not None and frame.left.shape == (240, 320)
            device.unplug()
            start = time.monotonic()
            with pytest.raises(DisconnectedError):
                while True:  # frames already queued on the host may still come out first
                    camera.get_frame(timeout=2.0)  # a CameraTimeoutError would fail here
            assert time.monotonic() - start < budget(5.0)
    finally:
        device.unplug()
        cam.close()
