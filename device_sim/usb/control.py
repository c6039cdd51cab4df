"""Endpoint 0 of a simulated device: the standard requests (USB 2.0 chapter 9) a vendor-class
camera answers; every other request STALLs (EPIPE), as on real hardware."""
from __future__ import annotations

import struct
from typing import TYPE_CHECKING

from .descriptors import DT_CONFIG, DT_DEVICE, DT_STRING, INTERFACE_NUMBER
from .errors import LibusbError, usb_error

if TYPE_CHECKING:
    from .device import SimHandle, SimUsbDevice

# Standard requests (USB 2.0 table 9-4).
GET_STATUS, CLEAR_FEATURE, SET_FEATURE = 0x00, 0x01, 0x03
GET_DESCRIPTOR, GET_CONFIGURATION, SET_CONFIGURATION = 0x06, 0x08, 0x09
GET_INTERFACE, SET_INTERFACE = 0x0A, 0x0B
FEATURE_ENDPOINT_HALT = 0


def control_transfer(device: "SimUsbDevice", handle: "SimHandle", request_type: int, request: int, value: int,
                     index: int, data: memoryview) -> int:
    """A control transfer on ``device``'s endpoint 0; returns the byte count (IN: written into ``data``)."""
    handle.check()
    if request_type & 0x80:
        reply = _control_in(device, request_type, request, value, index)
        n = min(len(reply), len(data))
        data[:n] = reply[:n]
        return n
    _control_out(device, handle, request_type, request, value, index)
    return len(data)


def _control_in(device: "SimUsbDevice", request_type: int, request: int, value: int, index: int) -> bytes:
    d = device.descriptors
    if request_type == 0x80 and request == GET_DESCRIPTOR:
        kind, number = value >> 8, value & 0xFF
        if kind == DT_DEVICE and number == 0:
            return d.device.pack()
        if kind == DT_CONFIG and number < len(d.configurations):
            return d.configurations[number].pack()
        if kind == DT_STRING:
            text = d.string(number, index)
            if text is not None:
                return text
    elif request_type == 0x80 and request == GET_CONFIGURATION:
        return bytes((device.configuration,))
    elif request_type == 0x80 and request == GET_STATUS:
        return b"\x00\x00"  # bus powered, no remote wakeup
    elif request_type == 0x81 and request in (GET_STATUS, GET_INTERFACE):
        if index == INTERFACE_NUMBER:
            return b"\x00\x00" if request == GET_STATUS else b"\x00"
    elif request_type == 0x82 and request == GET_STATUS:
        return struct.pack("<H", int(device.endpoint(index).halted))
    raise usb_error(LibusbError.PIPE, f"request 0x{request_type:02x}/0x{request:02x} stalled")


def _control_out(device: "SimUsbDevice", handle: "SimHandle", request_type: int, request: int, value: int,
                 index: int) -> None:
    if request_type == 0x00 and request == SET_CONFIGURATION:
        device.set_configuration(handle, value)
    elif request_type == 0x02 and request in (CLEAR_FEATURE, SET_FEATURE) and value == FEATURE_ENDPOINT_HALT:
        pipe = device.endpoint(index)
        pipe.clear_halt() if request == CLEAR_FEATURE else pipe.halt()
    elif not (request_type == 0x01 and request == SET_INTERFACE and index == INTERFACE_NUMBER and value == 0):
        raise usb_error(LibusbError.PIPE, f"request 0x{request_type:02x}/0x{request:02x} stalled")
