"""Simulated USB: a bus that simulated cameras plug into and out of at run time, seen by pyusb.

    import usb.core, device_sim.usb as simusb
    handle = simusb.plug(SimulatedCamera(serial="SC0001"), speed="super")  # or "high" (USB 2.0)
    dev = usb.core.find(backend=simusb.get_backend(), idVendor=simusb.VENDOR_ID)
    ...
    handle.unplug()

Every device has full USB descriptors (VID:PID 0x1209:0x0001, bcdDevice =
firmware version, manufacturer/product/serial strings), one configuration and one
vendor-specific interface with bulk OUT 0x01 and bulk IN 0x81. A unit enumerates at the speed
it is plugged at: high speed (USB 2.0: bcdUSB 2.00, 512-byte bulk packets, ~40 MB/s of bulk
payload) or super speed (USB 3.x: 3.20, 1024-byte packets, ~400 MB/s); its bulk IN pipe keeps
to that rate (``descriptors.SPEEDS``). ``pipes`` documents the transfer rules (packets, ZLP,
timeouts, bus time); errors are libusb1's (``errors``).
"""
from __future__ import annotations

from functools import wraps
from typing import Callable, Concatenate, ParamSpec, TypeVar

from .backend import SimBackend
from .bus import SimUsbBus
from .descriptors import (EP_IN, EP_OUT, INTERFACE_NUMBER, MAX_PACKET_SIZE, PRODUCT_ID,
                          VENDOR_ID, bcd_version)
from .device import SimHandle, SimUsbDevice, UsbFunction
from .errors import LibusbError, usb_error

_P = ParamSpec("_P")
_R = TypeVar("_R")

BUS = SimUsbBus(number=1)
"""The process-wide bus that ``plug()`` uses and ``stereocam.transports.usb`` scans (``get_backend``
is the ``stereocam.usb_backends`` entry point)."""


def _on_default_bus(method: Callable[Concatenate[SimUsbBus, _P], _R]) -> Callable[_P, _R]:
    """``method`` of whichever bus ``BUS`` is when called (a test may put its own in place)."""
    @wraps(method)
    def call(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        return method(BUS, *args, **kwargs)
    return call


plug = _on_default_bus(SimUsbBus.plug)
"""Plug a sim into the default bus (``SimUsbBus.plug``: speed, serial, product, firmware_version,
zlp, ...); ``handle.unplug()`` pulls it out again."""


def get_backend() -> SimBackend:
    """The pyusb backend of the default bus."""
    return BUS.backend


def plugged_devices() -> list[SimUsbDevice]:
    """Devices on the default bus now."""
    return BUS.devices


def unplug_all() -> None:
    """Unplug everything from the default bus."""
    BUS.unplug_all()


__all__ = ["BUS", "plug", "get_backend", "plugged_devices", "unplug_all", "SimUsbBus",
           "SimUsbDevice", "SimHandle", "SimBackend", "UsbFunction", "LibusbError", "usb_error",
           "VENDOR_ID", "PRODUCT_ID", "EP_IN", "EP_OUT", "INTERFACE_NUMBER", "MAX_PACKET_SIZE",
           "bcd_version"]
