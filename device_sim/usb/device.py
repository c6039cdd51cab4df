"""One simulated USB device: descriptors, endpoint 0 requests, bulk pipes, and its firmware thread.

It wraps any byte-level firmware (``function.UsbFunction``, e.g. ``SimulatedCamera``). Bulk OUT
transfers go to ``receive`` in order on the device's own firmware thread (a host write never waits
for a command to finish, as on real hardware); what the firmware sends is queued on bulk IN.
"""
from __future__ import annotations

import itertools
import logging
import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable

from .control import control_transfer
from .descriptors import CONFIGURATION_VALUE, EP_IN, EP_OUT, INTERFACE_NUMBER, BusSpeed, DescriptorSet
from .errors import LibusbError, usb_error
from .function import UsbFunction
from .pipes import InPipe, OutPipe

if TYPE_CHECKING:
    from .bus import SimUsbBus

_log = logging.getLogger(__name__)

IN_FIFO_SECONDS = 0.025  # the device's IN FIFO holds about this much of its bus's time
MIN_IN_CAPACITY = 1024 * 1024
DEFAULT_OUT_CAPACITY = 64 * 1024


_handle_ids = itertools.count(1)


@dataclass(eq=False)
class SimHandle:
    """An open device handle (what ``libusb_open`` returns)."""

    device: "SimUsbDevice"
    id: int = field(default_factory=lambda: next(_handle_ids))
    closed: bool = False

    def check(self) -> None:
        """Raise the pyusb error for I/O on this handle now (closed handle or unplugged)."""
        if not self.device.plugged:
            raise usb_error(LibusbError.NO_DEVICE)
        if self.closed:
            raise usb_error(LibusbError.IO, "device handle closed")


class SimUsbDevice:
    """A device plugged into a ``SimUsbBus``; ``bus.plug()`` returns it. ``unplug()`` pulls the
    cable: pending and later I/O fail with ENODEV, the firmware is detached, and blocked
    firmware writers get ``BrokenPipeError``."""

    def __init__(self, bus: "SimUsbBus", sim: UsbFunction, descriptors: DescriptorSet,
                 port: int, address: int, speed: BusSpeed, zlp: bool = True,
                 in_capacity: int | None = None,
                 out_capacity: int = DEFAULT_OUT_CAPACITY) -> None:
        self.bus = bus
        self.sim = sim
        self.descriptors = descriptors
        self.port = port
        self.address = address
        self.speed = speed
        self.plugged = True
        self.configuration = CONFIGURATION_VALUE  # the OS configures a device on enumeration
        self.claims: dict[int, SimHandle] = {}
        if in_capacity is None:
            in_capacity = max(MIN_IN_CAPACITY, int(speed.bulk_bytes_per_s * IN_FIFO_SECONDS))
        self.in_pipe = InPipe(EP_IN, speed.max_packet, in_capacity, zlp=zlp, bytes_per_s=speed.bulk_bytes_per_s)
        self.out_pipe = OutPipe(EP_OUT, out_capacity)
        self._lock = threading.RLock()
        self._handles: set[SimHandle] = set()
        self._thread = threading.Thread(target=self._firmware_loop, daemon=True,
                                        name=f"usb-sim-{bus.number}-{address}")
        if hasattr(sim, "usb_speed"):  # firmware that reports its link speed (INFO) reads it from here
            sim.usb_speed = speed.libusb_speed
        self.replug: Callable[[], SimUsbDevice] | None = None  # set by the bus: enumerate again after a reboot
        self.successor: SimUsbDevice | None = None  # this unit's next enumeration, after a reboot
        self._cable = threading.Lock()  # a reboot's re-enumeration and a pulled cable never interleave
        self._cable_pulled = False
        on_power = getattr(sim, "on_power", None)
        self._unsubscribe = on_power(self._on_power) if on_power is not None else (lambda: None)
        self._link_up()
        self._thread.start()

    def __repr__(self) -> str:
        state = "plugged" if self.plugged else "unplugged"
        return (f"<SimUsbDevice bus {self.bus.number} address {self.address} "
                f"serial {self.serial!r} {state}>")

    @property
    def serial(self) -> str:
        return self.descriptors.strings.get(self.descriptors.device.iSerialNumber, "")

    # -- cable -------------------------------------------------------------------------------

    def _on_power(self, event: str) -> None:
        """The firmware reboots: it drops off the bus, and enumerates anew once it is up."""
        if event == "down":
            self._disconnect()
        elif event == "up":
            with self._cable:
                if self._cable_pulled or self.successor is not None or self.replug is None:
                    return  # a unit whose cable is out does not enumerate again
                self._unsubscribe()
                self.successor = self.replug()

    def unplug(self) -> None:
        """Pull the cable (from this unit, whichever enumeration it is in now); idempotent. Never
        blocks on the firmware for more than ~2 s. A reboot finishing meanwhile does not re-plug."""
        with self._cable:
            self._cable_pulled = True
            self._unsubscribe()
            successor = self.successor
        if successor is not None:
            successor.unplug()
        self._disconnect()

    def _disconnect(self) -> None:
        with self._lock:
            if not self.plugged:
                return
            self.plugged = False
            self.claims.clear()
        self.bus._remove(self)
        self.in_pipe.close()
        self.out_pipe.close()
        if hasattr(self.sim, "usb_speed"):
            self.sim.usb_speed = 0
        try:
            self.sim.detach()
        except Exception:  # a firmware bug must not stop the unplug
            _log.exception("detach() of %r failed", self.sim)
        if self._thread is not threading.current_thread():
            self._thread.join(2.0)
            if self._thread.is_alive():
                _log.warning("firmware of %r still busy 2 s after unplug", self)

    def halt(self, endpoint: int) -> None:
        """Fault injection: STALL ``endpoint`` as firmware does on a protocol error."""
        self.endpoint(endpoint).halt()

    def _link_up(self) -> None:
        """Link the firmware to the IN pipe. A firmware that drops a silent host (SPEC §9) hangs up
        by flushing the pipe (which also frees a blocked push); the next OUT transfer links it up
        again, with nothing of the old host's output left queued."""
        self.in_pipe.flush()
        self.sim.attach(self.in_pipe.push, self.in_pipe.flush)

    def _firmware_loop(self) -> None:
        while (chunk := self.out_pipe.take()) is not None:
            try:
                if not self.sim.attached and self.plugged:
                    self._link_up()
                self.sim.receive(chunk)
            except OSError:  # the sink is gone (unplugged mid-reply)
                break
            except Exception:  # keep running, like firmware with a fault handler
                _log.exception("firmware receive() failed on %r", self)

    # -- handles and interface claims (libusb_open, libusb_claim_interface) ---------------

    def open(self) -> SimHandle:
        with self._lock:
            if not self.plugged:
                raise usb_error(LibusbError.NO_DEVICE)
            handle = SimHandle(self)
            self._handles.add(handle)
            return handle

    def close(self, handle: SimHandle) -> None:
        with self._lock:
            handle.closed = True
            self._handles.discard(handle)
            for intf in [i for i, h in self.claims.items() if h is handle]:
                del self.claims[intf]
        self.in_pipe.wake()
        self.out_pipe.wake()

    def claim(self, handle: SimHandle, intf: int) -> None:
        with self._lock:
            handle.check()
            if self.configuration == 0 or intf != INTERFACE_NUMBER:
                raise usb_error(LibusbError.NOT_FOUND, f"no interface {intf}")
            owner = self.claims.get(intf)
            if owner is not None and owner is not handle:
                raise usb_error(LibusbError.BUSY, f"interface {intf} claimed by another handle")
            self.claims[intf] = handle

    def release(self, handle: SimHandle, intf: int) -> None:
        with self._lock:
            handle.check()
            if self.claims.get(intf) is not handle:
                raise usb_error(LibusbError.NOT_FOUND, f"interface {intf} not claimed")
            del self.claims[intf]

    def set_configuration(self, handle: SimHandle, value: int) -> None:
        with self._lock:
            handle.check()
            if value not in (0, CONFIGURATION_VALUE) and value != -1:
                raise usb_error(LibusbError.NOT_FOUND, f"no configuration {value}")
            if any(h is not handle for h in self.claims.values()):
                raise usb_error(LibusbError.BUSY, "an interface is claimed by another handle")
            self.configuration = max(value, 0)
        for pipe in (self.in_pipe, self.out_pipe):
            pipe.clear_halt()

    def reset(self, handle: SimHandle) -> None:
        """Port reset: endpoint state and queued data are lost; handles and claims survive."""
        handle.check()
        for pipe in (self.in_pipe, self.out_pipe):
            pipe.flush()
            pipe.clear_halt()

    # -- bulk transfers --------------------------------------------------------------------

    def endpoint(self, endpoint: int) -> InPipe | OutPipe:
        """The pipe of ``endpoint`` (EP_IN or EP_OUT)."""
        if endpoint == EP_IN:
            return self.in_pipe
        if endpoint == EP_OUT:
            return self.out_pipe
        raise usb_error(LibusbError.NOT_FOUND, f"no endpoint 0x{endpoint:02x}")

    def _prepare_io(self, handle: SimHandle, endpoint: int) -> InPipe | OutPipe:
        """Checks before a transfer; like usbfs, an unclaimed interface is claimed implicitly."""
        handle.check()
        if self.configuration == 0:
            raise usb_error(LibusbError.NOT_FOUND, "device not configured")
        pipe = self.endpoint(endpoint)
        if self.claims.get(INTERFACE_NUMBER) is not handle:
            self.claim(handle, INTERFACE_NUMBER)
        return pipe

    def bulk_read(self, handle: SimHandle, endpoint: int, out: memoryview, timeout_ms: int) -> int:
        pipe = self._prepare_io(handle, endpoint)
        if not isinstance(pipe, InPipe):
            raise usb_error(LibusbError.INVALID_PARAM, f"0x{endpoint:02x} is an OUT endpoint")
        return pipe.read_transfer(out, timeout_ms, handle.check)

    def bulk_write(self, handle: SimHandle, endpoint: int, data: memoryview, timeout_ms: int) -> int:
        pipe = self._prepare_io(handle, endpoint)
        if not isinstance(pipe, OutPipe):
            raise usb_error(LibusbError.INVALID_PARAM, f"0x{endpoint:02x} is an IN endpoint")
        return pipe.write_transfer(data, timeout_ms, handle.check)

    def clear_halt(self, handle: SimHandle, endpoint: int) -> None:
        handle.check()
        self.endpoint(endpoint).clear_halt()

    # -- endpoint 0 ------------------------------------------------------------------------

    def control(self, handle: SimHandle, request_type: int, request: int, value: int,
                index: int, data: memoryview) -> int:
        """A control transfer on endpoint 0 (see ``control``); returns the byte count."""
        return control_transfer(self, handle, request_type, request, value, index, data)
