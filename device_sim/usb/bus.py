"""A simulated USB bus: plug simulated cameras in and out at run time; pyusb sees them via
``bus.backend`` (an ``IBackend``), like devices on a real host controller."""
from __future__ import annotations

import threading
from functools import partial
from typing import TYPE_CHECKING

from .descriptors import PRODUCT_ID, VENDOR_ID, bus_speed, camera_descriptors
from .device import DEFAULT_OUT_CAPACITY, SimUsbDevice, UsbFunction

if TYPE_CHECKING:
    from .backend import SimBackend

MAX_ADDRESS = 127
ROOT_HUB_ADDRESS = 1


class SimUsbBus:
    """One root hub with ``ports`` ports. Thread-safe; plug/unplug from any thread."""

    def __init__(self, number: int = 1, ports: int = 15) -> None:
        self.number = number
        self.ports = ports
        self._lock = threading.Lock()
        self._devices: list[SimUsbDevice] = []
        self._next_address = ROOT_HUB_ADDRESS + 1
        self._backend: SimBackend | None = None

    def __repr__(self) -> str:
        return f"<SimUsbBus {self.number}: {len(self._devices)} device(s)>"

    @property
    def backend(self) -> "SimBackend":
        """The pyusb backend of this bus: ``usb.core.find(backend=bus.backend)``."""
        if self._backend is None:
            from .backend import SimBackend
            self._backend = SimBackend(self)
        return self._backend

    @property
    def devices(self) -> list[SimUsbDevice]:
        """Devices plugged in now, in plug order."""
        with self._lock:
            return list(self._devices)

    def plug(self, sim: UsbFunction, *, serial: str | None = None, product: str | None = None,
             firmware_version: str | None = None, vendor_id: int = VENDOR_ID,
             product_id: int = PRODUCT_ID, zlp: bool = True, speed: str = "high",
             in_capacity: int | None = None,
             out_capacity: int = DEFAULT_OUT_CAPACITY) -> SimUsbDevice:
        """Plug ``sim`` in; it enumerates at once, at ``speed`` ("high": USB 2.0, ~40 MB/s of bulk
        payload; "super": USB 3.x, ~400 MB/s), which its descriptors report and its bulk IN pipe
        keeps to. Descriptor strings default to the sim's ``serial``, ``model`` and
        ``firmware_version`` attributes. ``zlp=False`` models firmware that omits zero-length
        packets (see ``pipes``). ``in_capacity``: the device's IN FIFO (default: ~25 ms of the bus)."""
        link = bus_speed(speed)
        serial = serial if serial is not None else str(getattr(sim, "serial", ""))
        product = product if product is not None else str(getattr(sim, "model", "StereoCam"))
        version = firmware_version or str(getattr(sim, "firmware_version", "0.0.0"))
        descriptors = camera_descriptors(serial, product, version, vendor_id, product_id, link)
        with self._lock:
            if any(d.sim is sim for d in self._devices):
                raise ValueError(f"{sim!r} is already plugged into {self!r}")
            used_ports = {d.port for d in self._devices}
            port = next((p for p in range(1, self.ports + 1) if p not in used_ports), None)
            if port is None:
                raise RuntimeError(f"all {self.ports} ports of {self!r} are in use")
            address = self._allocate_address()
            device = SimUsbDevice(self, sim, descriptors, port, address, link, zlp=zlp,
                                  in_capacity=in_capacity, out_capacity=out_capacity)
            self._devices.append(device)
        device.replug = partial(self.plug, sim, vendor_id=vendor_id, product_id=product_id, zlp=zlp, speed=speed,
                                in_capacity=in_capacity, out_capacity=out_capacity)
        return device

    def unplug_all(self) -> None:
        """Unplug every device (test teardown)."""
        for device in self.devices:
            device.unplug()

    def _allocate_address(self) -> int:
        """Next free address in 2..127, round robin like host controller drivers do."""
        used = {d.address for d in self._devices}
        for _ in range(MAX_ADDRESS):
            address = self._next_address
            self._next_address = address + 1 if address < MAX_ADDRESS else ROOT_HUB_ADDRESS + 1
            if address not in used:
                return address
        raise RuntimeError(f"no free USB address on {self!r}")

    def _remove(self, device: SimUsbDevice) -> None:
        with self._lock:
            if device in self._devices:
                self._devices.remove(device)
