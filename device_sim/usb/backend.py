"""pyusb backend over a ``SimUsbBus``: what ``usb.core`` calls, answered the way libusb1's
backend answers (same descriptor attributes, same exceptions and error codes)."""
from __future__ import annotations

import array
from dataclasses import asdict
from types import SimpleNamespace
from typing import TYPE_CHECKING

import usb.backend

from .device import SimHandle, SimUsbDevice
from .errors import LibusbError, usb_error

if TYPE_CHECKING:
    from .bus import SimUsbBus


def _bytes_view(buffer: array.array) -> memoryview:
    return memoryview(buffer).cast("B")


class SimBackend(usb.backend.IBackend):
    """``usb.core.find(backend=SimBackend(bus))`` enumerates the bus's plugged devices.

    Device ids are ``SimUsbDevice`` objects and handles are ``SimHandle`` objects; like
    libusb, descriptors stay readable after an unplug, but opening or I/O fails with ENODEV.
    """

    def __init__(self, bus: "SimUsbBus") -> None:
        super().__init__()
        self.bus = bus

    def __repr__(self) -> str:
        return f"<SimBackend of {self.bus!r}>"

    # -- enumeration and descriptors -----------------------------------------------------

    def enumerate_devices(self) -> list[SimUsbDevice]:
        return self.bus.devices

    def get_parent(self, dev: SimUsbDevice) -> None:
        return None  # plugged straight into the root hub, which is not modelled as a device

    def get_device_descriptor(self, dev: SimUsbDevice) -> SimpleNamespace:
        return SimpleNamespace(**asdict(dev.descriptors.device), bus=dev.bus.number,
                               address=dev.address, port_number=dev.port,
                               port_numbers=(dev.port,), speed=dev.speed.libusb_speed)

    def get_configuration_descriptor(self, dev: SimUsbDevice, config: int) -> SimpleNamespace:
        configs = dev.descriptors.configurations
        if not 0 <= config < len(configs):
            raise usb_error(LibusbError.NOT_FOUND, f"no configuration index {config}")
        cfg = configs[config]
        fields = {k: v for k, v in asdict(cfg).items() if k != "interfaces"}
        return SimpleNamespace(**fields, bNumInterfaces=cfg.bNumInterfaces,
                               wTotalLength=cfg.wTotalLength, extra_descriptors=[])

    def _interface(self, dev: SimUsbDevice, intf: int, alt: int, config: int):
        cfg = dev.descriptors.configurations[config]
        numbers = sorted({i.bInterfaceNumber for i in cfg.interfaces})
        if intf >= len(numbers):
            raise IndexError(f"Invalid interface index {intf}")
        alts = [i for i in cfg.interfaces if i.bInterfaceNumber == numbers[intf]]
        if alt >= len(alts):
            raise IndexError(f"Invalid alternate setting index {alt}")
        return alts[alt]

    def get_interface_descriptor(self, dev: SimUsbDevice, intf: int, alt: int,
                                 config: int) -> SimpleNamespace:
        desc = self._interface(dev, intf, alt, config)
        fields = {k: v for k, v in asdict(desc).items() if k != "endpoints"}
        return SimpleNamespace(**fields, bNumEndpoints=desc.bNumEndpoints, extra_descriptors=[])

    def get_endpoint_descriptor(self, dev: SimUsbDevice, ep: int, intf: int, alt: int,
                                config: int) -> SimpleNamespace:
        endpoints = self._interface(dev, intf, alt, config).endpoints
        if ep >= len(endpoints):
            raise IndexError(f"Invalid endpoint index {ep}")
        return SimpleNamespace(**asdict(endpoints[ep]), extra_descriptors=[])

    # -- handles ---------------------------------------------------------------------------

    def open_device(self, dev: SimUsbDevice) -> SimHandle:
        return dev.open()

    def close_device(self, dev_handle: SimHandle) -> None:
        dev_handle.device.close(dev_handle)

    def set_configuration(self, dev_handle: SimHandle, config_value: int) -> None:
        dev_handle.device.set_configuration(dev_handle, config_value)

    def get_configuration(self, dev_handle: SimHandle) -> int:
        dev_handle.check()
        return dev_handle.device.configuration

    def set_interface_altsetting(self, dev_handle: SimHandle, intf: int, altsetting: int) -> None:
        dev_handle.check()
        if altsetting != 0:
            raise usb_error(LibusbError.NOT_FOUND, f"no alternate setting {altsetting}")

    def claim_interface(self, dev_handle: SimHandle, intf: int) -> None:
        dev_handle.device.claim(dev_handle, intf)

    def release_interface(self, dev_handle: SimHandle, intf: int) -> None:
        dev_handle.device.release(dev_handle, intf)

    # -- transfers -------------------------------------------------------------------------

    def bulk_write(self, dev_handle: SimHandle, ep: int, intf: int, data: array.array,
                   timeout: int) -> int:
        return dev_handle.device.bulk_write(dev_handle, ep, _bytes_view(data), timeout)

    def bulk_read(self, dev_handle: SimHandle, ep: int, intf: int, buff: array.array,
                  timeout: int) -> int:
        return dev_handle.device.bulk_read(dev_handle, ep, _bytes_view(buff), timeout)

    def ctrl_transfer(self, dev_handle: SimHandle, bmRequestType: int, bRequest: int,
                      wValue: int, wIndex: int, data: array.array, timeout: int) -> int:
        return dev_handle.device.control(dev_handle, bmRequestType, bRequest, wValue, wIndex,
                                         _bytes_view(data))

    def clear_halt(self, dev_handle: SimHandle, ep: int) -> None:
        dev_handle.device.clear_halt(dev_handle, ep)

    def reset_device(self, dev_handle: SimHandle) -> None:
        dev_handle.device.reset(dev_handle)

    # -- kernel drivers: none is ever bound to a simulated device ----------------------------

    def is_kernel_driver_active(self, dev_handle: SimHandle, intf: int) -> bool:
        dev_handle.check()
        return False

    def detach_kernel_driver(self, dev_handle: SimHandle, intf: int) -> None:
        dev_handle.check()
        raise usb_error(LibusbError.NOT_FOUND, "no kernel driver bound")

    def attach_kernel_driver(self, dev_handle: SimHandle, intf: int) -> None:
        dev_handle.check()
        raise usb_error(LibusbError.NOT_FOUND, "no kernel driver to attach")
