"""The simulated USB bus, driven through pyusb's own core (usb.core / usb.util), not mocks."""
from __future__ import annotations

import errno
import struct
import threading
import time

import pytest
import usb.core
import usb.util

from stereocam.device_sim.usb import EP_IN, EP_OUT, PRODUCT_ID, VENDOR_ID, SimUsbBus, bcd_version
from stereocam.device_sim.usb.testdevices import EchoDevice, SourceDevice
from stereocam.tools.conformance.budget import budget
from tests.support.waiting import stays, wait_until


@pytest.fixture
def bus():
    bus = SimUsbBus(number=7)
    yield bus
    bus.unplug_all()


def find(bus: SimUsbBus, **match) -> usb.core.Device:
    dev = usb.core.find(backend=bus.backend, **match)
    assert dev is not None, f"no device matching {match}"
    return dev


def read(dev: usb.core.Device, size: int, timeout_ms: int = 1000) -> bytes:
    return bytes(dev.read(EP_IN, size, timeout_ms))


# -- enumeration and descriptors ----------------------------------------------------------------

def test_device_descriptor_fields_and_strings(bus):
    bus.plug(EchoDevice(serial="SN-42"))
    dev = find(bus, idVendor=VENDOR_ID, idProduct=PRODUCT_ID)
    assert (dev.idVendor, dev.idProduct) == (0x1209, 0x0001)
    assert dev.bcdUSB == 0x0200 and dev.bcdDevice == 0x0123  # EchoDevice firmware "1.2.3"
    assert dev.bDeviceClass == 0 and dev.bNumConfigurations == 1
    assert dev.speed == 3  # LIBUSB_SPEED_HIGH
    assert (dev.bus, dev.address) == (7, 2)
    assert dev.langids == (0x0409,)
    assert usb.util.get_string(dev, dev.iSerialNumber) == "SN-42"
    assert (dev.serial_number, dev.product, dev.manufacturer) == ("SN-42", "Echo", "StereoCam")
    assert "StereoCam bulk stream" in str(dev)  # pyusb's full dump reads every string


def test_configuration_interface_and_endpoints(bus):
    bus.plug(EchoDevice())
    dev = find(bus)
    cfg = dev.get_active_configuration()
    assert cfg.bConfigurationValue == 1 and cfg.bNumInterfaces == 1 and cfg.wTotalLength == 32
    intf = usb.util.find_descriptor(cfg, bInterfaceClass=0xFF)
    assert intf is not None and intf.bInterfaceNumber == 0 and intf.bNumEndpoints == 2
    ep_in = usb.util.find_descriptor(intf, custom_match=lambda e: usb.util.endpoint_direction(
        e.bEndpointAddress) == usb.util.ENDPOINT_IN)
    ep_out = usb.util.find_descriptor(intf, custom_match=lambda e: usb.util.endpoint_direction(
        e.bEndpointAddress) == usb.util.ENDPOINT_OUT)
    for ep, address in ((ep_in, EP_IN), (ep_out, EP_OUT)):
        assert ep.bEndpointAddress == address
        assert usb.util.endpoint_type(ep.bmAttributes) == usb.util.ENDPOINT_TYPE_BULK
        assert ep.wMaxPacketSize == 512


def test_raw_descriptors_match_parsed_fields(bus):
    bus.plug(EchoDevice())
    dev = find(bus)
    raw = bytes(dev.ctrl_transfer(0x80, 6, 0x0100, 0, 18))
    fields = struct.unpack("<BBHBBBBHHHBBBB", raw)
    assert fields[:3] == (18, 1, dev.bcdUSB)
    assert fields[7:10] == (dev.idVendor, dev.idProduct, dev.bcdDevice)
    head = bytes(dev.ctrl_transfer(0x80, 6, 0x0200, 0, 9))  # config header first, like an OS
    total = struct.unpack_from("<H", head, 2)[0]
    full = bytes(dev.ctrl_transfer(0x80, 6, 0x0200, 0, total))
    assert len(full) == total == 32
    assert [full[i + 2] for i in (18, 25)] == [EP_OUT, EP_IN]  # endpoint descriptors follow
    with pytest.raises(usb.core.USBError) as err:  # a string the device does not have stalls
        dev.ctrl_transfer(0x80, 6, 0x0309, 0x0409, 255)
    assert err.value.errno == errno.EPIPE


@pytest.mark.parametrize("version,bcd", [("1.0.0", 0x0100), ("1.2.3", 0x0123),
                                         ("12.3.4", 0x1234), ("2.15.0", 0x0290), ("7", 0x0700)])
def test_bcd_version(version, bcd):
    assert bcd_version(version) == bcd


def test_plug_unplug_replug_enumeration(bus):
    a, b = EchoDevice(serial="A"), EchoDevice(serial="B")
    handle_a = bus.plug(a)
    bus.plug(b)
    devices = list(usb.core.find(find_all=True, backend=bus.backend))
    assert [d.serial_number for d in devices] == ["A", "B"]
    assert len({d.address for d in devices}) == 2
    assert find(bus, custom_match=lambda d: d.serial_number == "B").address == devices[1].address
    with pytest.raises(ValueError):
        bus.plug(a)  # already plugged
    handle_a.unplug()
    assert [d.serial_number for d in usb.core.find(find_all=True, backend=bus.backend)] == ["B"]
    again = bus.plug(a)
    assert again.address not in {d.address for d in devices}  # a fresh address, as on real USB


class RebootingDevice(EchoDevice):
    """An echo firmware that tells its listeners when it goes down and comes up (as a reboot does)."""

    def __init__(self, serial: str = "REBOOT1") -> None:
        super().__init__(serial)
        self.listeners: list = []

    def on_power(self, listener):
        self.listeners.append(listener)
        return lambda: self.listeners.remove(listener) if listener in self.listeners else None

    def notify(self, event: str, listeners=None) -> None:
        for listener in list(self.listeners if listeners is None else listeners):
            listener(event)


def test_a_reboot_re_enumerates_the_unit(bus):
    sim = RebootingDevice()
    first = bus.plug(sim)
    sim.notify("down")
    assert bus.devices == []
    sim.notify("up")
    assert [d.sim for d in bus.devices] == [sim] and first.successor is bus.devices[0]
    first.unplug()  # the cable, from whichever enumeration the unit is in
    assert bus.devices == []


def test_a_reboot_finishing_after_the_cable_is_pulled_does_not_plug_the_unit_back(bus):
    sim = RebootingDevice()
    handle = bus.plug(sim)
    in_flight = list(sim.listeners)  # the firmware took its listener list before the cable went
    sim.notify("down")
    handle.unplug()
    sim.notify("up", in_flight)
    assert bus.devices == []
    assert bus.plug(sim).sim is sim  # plugged again by hand, not "already plugged"


# -- claiming -----------------------------------------------------------------------------------

def test_second_claim_from_another_handle_is_busy(bus):
    bus.plug(EchoDevice())
    first, second = find(bus), find(bus)  # two Device objects: two open handles
    usb.util.claim_interface(first, 0)
    with pytest.raises(usb.core.USBError) as err:
        usb.util.claim_interface(second, 0)
    assert err.value.errno == errno.EBUSY and err.value.backend_error_code == -6
    with pytest.raises(usb.core.USBError):  # the implicit claim of a transfer fails as well
        second.write(EP_OUT, b"x", 100)
    usb.util.dispose_resources(first)  # closes the handle, releasing the claim
    usb.util.claim_interface(second, 0)
    second.write(EP_OUT, b"ok", 100)
    assert read(second, 512) == b"ok"


# -- bulk transfers -----------------------------------------------------------------------------

def test_write_reaches_firmware_in_order_and_echoes(bus):
    echo = EchoDevice()
    bus.plug(echo)
    dev = find(bus)
    payload = bytes(range(256)) * 4096  # 1 MiB
    assert dev.write(EP_OUT, payload, 2000) == len(payload)
    got = bytearray()
    while len(got) < len(payload):
        got += read(dev, 64 * 1024)
    assert bytes(got) == payload
    assert b"".join(echo.received) == payload


def test_short_packet_ends_each_device_transfer(bus):
    echo = EchoDevice()
    bus.plug(echo)
    dev = find(bus)
    echo.send(b"a" * 1000)
    echo.send(b"b" * 100)
    assert read(dev, 64 * 1024) == b"a" * 1000  # 512 + 488: the short packet ends the read
    assert read(dev, 64 * 1024) == b"b" * 100


def test_read_takes_whole_packets_up_to_the_buffer(bus):
    echo = EchoDevice()
    bus.plug(echo)
    dev = find(bus)
    echo.send(bytes(range(256)) * 6)  # 1536 bytes: three full packets, then a ZLP
    assert read(dev, 1024) == (bytes(range(256)) * 6)[:1024]
    assert read(dev, 1024) == (bytes(range(256)) * 6)[1024:]


def test_zero_length_packet_ends_a_transfer_of_whole_packets(bus):
    echo = EchoDevice()
    bus.plug(echo)
    dev = find(bus)
    echo.send(b"z" * 1024)
    start = time.monotonic()
    assert read(dev, 64 * 1024, timeout_ms=10_000) == b"z" * 1024
    assert time.monotonic() - start < budget(0.5)  # ended by the ZLP, not by the timeout
    echo.send(b"y" * 1024)
    assert read(dev, 1024) == b"y" * 1024  # buffer full: the ZLP stays queued ...
    assert read(dev, 1024) == b""  # ... and completes the next read with zero bytes
    with pytest.raises(usb.core.USBTimeoutError):
        read(dev, 1024, timeout_ms=50)


def test_without_zlp_a_read_waits_for_its_timeout_and_returns_partial_data(bus):
    echo = EchoDevice()
    bus.plug(echo, zlp=False)
    dev = find(bus)
    echo.send(b"q" * 1024)
    start = time.monotonic()
    assert read(dev, 64 * 1024, timeout_ms=200) == b"q" * 1024  # libusb: partial data on timeout
    assert time.monotonic() - start >= 0.18


def test_read_timeout_is_pyusb_timeout_error(bus):
    bus.plug(EchoDevice())
    dev = find(bus)
    start = time.monotonic()
    with pytest.raises(usb.core.USBTimeoutError) as err:
        read(dev, 512, timeout_ms=100)
    assert err.value.errno == errno.ETIMEDOUT and err.value.backend_error_code == -7
    assert 0.09 <= time.monotonic() - start < budget(1.0)


def test_packet_larger_than_the_buffer_overflows(bus):
    echo = EchoDevice()
    bus.plug(echo)
    dev = find(bus)
    echo.send(b"o" * 100)
    with pytest.raises(usb.core.USBError) as err:
        read(dev, 50)
    assert err.value.errno == errno.EOVERFLOW


def test_full_fifo_blocks_the_firmware_until_the_host_reads(bus):
    source = SourceDevice(chunk=8 * 1024)
    bus.plug(source, in_capacity=32 * 1024)
    dev = find(bus)
    total = 1024 * 1024
    dev.write(EP_OUT, str(total).encode(), 100)
    pipe = bus.devices[0].in_pipe
    wait_until(lambda: pipe.queued >= 24 * 1024, what="the firmware fills the FIFO")
    assert stays(lambda: pipe.queued <= 32 * 1024, 0.1)  # flow control holds the firmware back
    got = bytearray()
    while len(got) < total:
        got += read(dev, 16 * 1024)
    assert bytes(got) == (bytes(range(256)) * 32)[:8192] * (total // 8192)
    assert source.error is None


def test_write_times_out_with_the_partial_count_when_the_firmware_stalls(bus):
    gate = threading.Event()

    class Slow(EchoDevice):
        def receive(self, data: bytes) -> None:
            gate.wait(5)

    bus.plug(Slow(), out_capacity=1024)
    dev = find(bus)
    try:
        sent = dev.write(EP_OUT, b"w" * 8192, 200)
        assert 1024 <= sent < 8192
    finally:
        gate.set()


# -- halts, control requests, reset -------------------------------------------------------------

def test_halted_endpoint_fails_with_epipe_until_clear_halt(bus):
    echo = EchoDevice()
    device = bus.plug(echo)
    dev = find(bus)
    device.halt(EP_IN)
    echo.send(b"data")
    with pytest.raises(usb.core.USBError) as err:
        read(dev, 512)
    assert err.value.errno == errno.EPIPE and err.value.backend_error_code == -9
    assert bytes(dev.ctrl_transfer(0x82, 0, 0, EP_IN, 2)) == b"\x01\x00"  # GET_STATUS: halted
    dev.clear_halt(EP_IN)
    assert bytes(dev.ctrl_transfer(0x82, 0, 0, EP_IN, 2)) == b"\x00\x00"
    assert read(dev, 512) == b"data"
    dev.ctrl_transfer(0x02, 3, 0, EP_OUT)  # SET_FEATURE(ENDPOINT_HALT) from the host side
    with pytest.raises(usb.core.USBError):
        dev.write(EP_OUT, b"x", 100)
    dev.ctrl_transfer(0x02, 1, 0, EP_OUT)  # CLEAR_FEATURE(ENDPOINT_HALT)
    assert dev.write(EP_OUT, b"x", 100) == 1


def test_standard_requests_and_unknown_request_stalls(bus):
    bus.plug(EchoDevice())
    dev = find(bus)
    assert bytes(dev.ctrl_transfer(0x80, 8, 0, 0, 1)) == b"\x01"  # GET_CONFIGURATION
    dev.set_configuration(0)
    assert bytes(dev.ctrl_transfer(0x80, 8, 0, 0, 1)) == b"\x00"
    dev.set_configuration()
    assert dev.get_active_configuration().bConfigurationValue == 1
    with pytest.raises(usb.core.USBError) as err:
        dev.ctrl_transfer(0xC0, 0x42, 0, 0, 4)  # a vendor request the firmware does not know
    assert err.value.errno == errno.EPIPE


def test_reset_drops_queued_data(bus):
    echo = EchoDevice()
    bus.plug(echo)
    dev = find(bus)
    echo.send(b"stale")
    dev.reset()
    with pytest.raises(usb.core.USBTimeoutError):
        read(dev, 512, timeout_ms=50)
    dev.write(EP_OUT, b"fresh", 100)
    assert read(dev, 512) == b"fresh"


# -- unplug -------------------------------------------------------------------------------------

def test_unplug_fails_io_with_enodev(bus):
    device = bus.plug(EchoDevice())
    dev = find(bus)
    dev.write(EP_OUT, b"hi", 100)
    device.unplug()
    for op in (lambda: read(dev, 512), lambda: dev.write(EP_OUT, b"x", 100),
               lambda: dev.ctrl_transfer(0x80, 8, 0, 0, 1), lambda: dev.clear_halt(EP_IN)):
        with pytest.raises(usb.core.USBError) as err:
            op()
        assert err.value.errno == errno.ENODEV and err.value.backend_error_code == -4
    device.unplug()  # idempotent
    assert dev.idVendor == VENDOR_ID  # descriptors stay readable, as with libusb


def test_unplug_wakes_a_pending_read_at_once(bus):
    device = bus.plug(EchoDevice())
    dev = find(bus)
    outcome: list[BaseException] = []

    def reader() -> None:
        try:
            read(dev, 64 * 1024, timeout_ms=10_000)
        except usb.core.USBError as exc:
            outcome.append(exc)

    thread = threading.Thread(target=reader)
    thread.start()
    wait_until(lambda: device.in_pipe.waiting, what="the read waits for data")
    start = time.monotonic()
    device.unplug()
    thread.join(2)
    assert not thread.is_alive() and time.monotonic() - start < budget(1.0)
    assert outcome and outcome[0].errno == errno.ENODEV


def test_unplug_unblocks_a_firmware_writer_with_broken_pipe(bus):
    echo = EchoDevice()
    device = bus.plug(echo, in_capacity=1024)
    echo.send(b"f" * 1024)  # fills the FIFO
    errors: list[BaseException] = []

    def writer() -> None:
        try:
            echo.send(b"g" * 1024)  # blocks: nobody reads
        except OSError as exc:
            errors.append(exc)

    thread = threading.Thread(target=writer)
    thread.start()
    wait_until(lambda: device.in_pipe.waiting, what="the firmware's push waits for room")
    assert thread.is_alive()
    device.unplug()
    thread.join(2)
    assert not thread.is_alive() and isinstance(errors[0], BrokenPipeError)


def test_open_after_unplug_fails_with_enodev(bus):
    device = bus.plug(EchoDevice())
    dev = find(bus)
    device.unplug()
    with pytest.raises(usb.core.USBError) as err:
        dev.set_configuration()
    assert err.value.errno == errno.ENODEV


# -- bus speed ------------------------------------------------------------------------------------

@pytest.mark.parametrize("speed,libusb_speed,bcd_usb,packet", [("high", 3, 0x0200, 512), ("super", 4, 0x0320, 1024)])
def test_descriptors_follow_the_bus_speed(bus, speed, libusb_speed, bcd_usb, packet):
    bus.plug(EchoDevice(serial=speed), speed=speed)
    dev = find(bus)
    assert (dev.speed, dev.bcdUSB) == (libusb_speed, bcd_usb)
    intf = dev.get_active_configuration()[(0, 0)]
    assert [ep.wMaxPacketSize for ep in intf] == [packet, packet]
    raw = bytes(dev.ctrl_transfer(0x80, 6, 0x0200, 0, 32))
    assert struct.unpack_from("<H", raw, 18 + 4)[0] == packet  # the wire bytes say the same
    dev.write(EP_OUT, b"x" * 3000)
    assert read(dev, 4096) == b"x" * 3000


def test_unknown_bus_speed_is_refused(bus):
    with pytest.raises(ValueError, match="known: high, super"):
        bus.plug(EchoDevice(), speed="full")


def test_high_speed_bus_caps_bulk_throughput(bus):
    """USB 2.0 carries ~40 MB/s of bulk payload: a host cannot read a fast source faster."""
    bus.plug(SourceDevice(serial="FAST", chunk=1 << 20), speed="high")
    dev = find(bus)
    total = 6_000_000
    dev.write(EP_OUT, str(total).encode())
    got, start = 0, time.monotonic()
    while got < total:
        got += len(dev.read(EP_IN, 256 * 1024, 2000))
    rate = total / (time.monotonic() - start)
    assert rate < 48e6  # 40 MB/s plus slack for the first transfer's start


@pytest.mark.parametrize("speed,reported", [("high", 3), ("super", 4)])
def test_info_says_which_speed_the_unit_is_plugged_at(speed, reported):
    import stereocam
    import stereocam.device_sim.usb as simusb
    from stereocam.device_sim import SimulatedCamera
    from stereocam.protocol import messages as m

    sim = SimulatedCamera(serial=f"INFO-{speed}", seed=43)
    handle = simusb.plug(sim, speed=speed)
    try:
        with stereocam.open(f"usb://?serial=INFO-{speed}", timeout=3.0) as cam:
            assert cam.request(m.GetInfo()).usb_speed == reported
    finally:
        handle.unplug()
    assert sim.usb_speed == m.UsbSpeed.NOT_USB  # unplugged: on no USB link
    sim.close()
