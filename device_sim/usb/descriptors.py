"""USB descriptors of a simulated camera: typed fields plus their exact wire bytes (USB 2.0 ch. 9).

The same dataclasses feed both pyusb's attribute view (``usb.core.Device.idVendor``, ...) and
the bytes a GET_DESCRIPTOR control request returns, so the two can never disagree.
"""
from __future__ import annotations

import re
import struct
from dataclasses import dataclass, field

from stereocam.protocol.messages import UsbSpeed
from stereocam.protocol.usb_identity import (EP_IN, EP_OUT, INTERFACE_NUMBER, PRODUCT_ID,
                                             VENDOR_ID)
from stereocam.protocol.usb_identity import INTERFACE_CLASS as CLASS_VENDOR_SPECIFIC
from stereocam.protocol.usb_identity import MAX_PACKET_SIZE_HS as MAX_PACKET_SIZE
from stereocam.protocol.usb_identity import MAX_PACKET_SIZE_SS

CONFIGURATION_VALUE = 1
LANGID_EN_US = 0x0409
MANUFACTURER = "StereoCam"
INTERFACE_NAME = "StereoCam bulk stream"

DT_DEVICE, DT_CONFIG, DT_STRING, DT_INTERFACE, DT_ENDPOINT = 1, 2, 3, 4, 5
ATTR_BULK = 0x02
SPEED_HIGH = UsbSpeed.HIGH
"""libusb_speed value for USB 2.0 high speed (480 Mbit/s); INFO reports the same numbers."""
SPEED_SUPER = UsbSpeed.SUPER
"""libusb_speed value for USB 3.x super speed (5 Gbit/s)."""


@dataclass(frozen=True)
class BusSpeed:
    """How fast a unit's link is: what its descriptors say and how many bulk payload bytes per
    second the bus carries (protocol overhead, other traffic and host scheduling taken off)."""

    name: str
    libusb_speed: int
    bcd_usb: int
    max_packet: int
    bulk_bytes_per_s: float


SPEEDS = {
    "high": BusSpeed("high", SPEED_HIGH, 0x0200, MAX_PACKET_SIZE, 40e6),  # 480 Mbit/s: ~40 MB/s of bulk in practice
    "super": BusSpeed("super", SPEED_SUPER, 0x0320, MAX_PACKET_SIZE_SS, 400e6),  # 5 Gbit/s: ~400 MB/s
}


def bus_speed(name: str) -> BusSpeed:
    """The speed called ``name`` ("high" or "super"); ValueError naming the known ones otherwise."""
    try:
        return SPEEDS[name]
    except KeyError:
        raise ValueError(f"unknown USB speed {name!r}; known: {', '.join(SPEEDS)}") from None


def bcd_version(version: str) -> int:
    """Firmware version "J.M.N" → bcdDevice 0xJJMN (USB's binary-coded decimal release number).

    Fields that do not fit (major > 99, minor or patch > 9) are clamped; missing fields are 0.
    """
    parts = [int(p) for p in re.findall(r"\d+", version)[:3]] + [0, 0, 0]
    major, minor, patch = min(parts[0], 99), min(parts[1], 9), min(parts[2], 9)
    return ((major // 10) << 12) | ((major % 10) << 8) | (minor << 4) | patch


@dataclass(frozen=True)
class EndpointDescriptor:
    bEndpointAddress: int
    bmAttributes: int = ATTR_BULK
    wMaxPacketSize: int = MAX_PACKET_SIZE
    bInterval: int = 0
    bLength: int = 7
    bDescriptorType: int = DT_ENDPOINT
    bRefresh: int = 0
    bSynchAddress: int = 0

    def pack(self) -> bytes:
        return struct.pack("<BBBBHB", self.bLength, self.bDescriptorType, self.bEndpointAddress,
                           self.bmAttributes, self.wMaxPacketSize, self.bInterval)


@dataclass(frozen=True)
class InterfaceDescriptor:
    endpoints: tuple[EndpointDescriptor, ...]
    bInterfaceNumber: int = INTERFACE_NUMBER
    bAlternateSetting: int = 0
    bInterfaceClass: int = CLASS_VENDOR_SPECIFIC
    bInterfaceSubClass: int = 0
    bInterfaceProtocol: int = 0
    iInterface: int = 4
    bLength: int = 9
    bDescriptorType: int = DT_INTERFACE

    @property
    def bNumEndpoints(self) -> int:
        return len(self.endpoints)

    def pack(self) -> bytes:
        head = struct.pack("<9B", self.bLength, self.bDescriptorType, self.bInterfaceNumber,
                           self.bAlternateSetting, self.bNumEndpoints, self.bInterfaceClass,
                           self.bInterfaceSubClass, self.bInterfaceProtocol, self.iInterface)
        return head + b"".join(ep.pack() for ep in self.endpoints)


@dataclass(frozen=True)
class ConfigurationDescriptor:
    interfaces: tuple[InterfaceDescriptor, ...]
    bConfigurationValue: int = CONFIGURATION_VALUE
    iConfiguration: int = 0
    bmAttributes: int = 0x80  # bit 7 must be set; bus powered, no remote wakeup
    bMaxPower: int = 250  # in 2 mA units: 500 mA
    bLength: int = 9
    bDescriptorType: int = DT_CONFIG

    @property
    def bNumInterfaces(self) -> int:
        return len({i.bInterfaceNumber for i in self.interfaces})

    @property
    def wTotalLength(self) -> int:
        return len(self.pack())

    def pack(self) -> bytes:
        body = b"".join(i.pack() for i in self.interfaces)
        head = struct.pack("<BBHBBBBB", self.bLength, self.bDescriptorType, 9 + len(body),
                           self.bNumInterfaces, self.bConfigurationValue, self.iConfiguration,
                           self.bmAttributes, self.bMaxPower)
        return head + body


@dataclass(frozen=True)
class DeviceDescriptor:
    bcdDevice: int
    idVendor: int = VENDOR_ID
    idProduct: int = PRODUCT_ID
    bcdUSB: int = 0x0200
    bDeviceClass: int = 0  # class is given per interface
    bDeviceSubClass: int = 0
    bDeviceProtocol: int = 0
    bMaxPacketSize0: int = 64
    iManufacturer: int = 1
    iProduct: int = 2
    iSerialNumber: int = 3
    bNumConfigurations: int = 1
    bLength: int = 18
    bDescriptorType: int = DT_DEVICE

    def pack(self) -> bytes:
        return struct.pack("<BBHBBBBHHHBBBB", self.bLength, self.bDescriptorType, self.bcdUSB,
                           self.bDeviceClass, self.bDeviceSubClass, self.bDeviceProtocol,
                           self.bMaxPacketSize0, self.idVendor, self.idProduct, self.bcdDevice,
                           self.iManufacturer, self.iProduct, self.iSerialNumber,
                           self.bNumConfigurations)


def string_descriptor(text: str) -> bytes:
    """A string descriptor: bLength, bDescriptorType=3, UTF-16LE text (at most 126 characters)."""
    payload = text.encode("utf-16-le")[:252]
    return bytes((2 + len(payload), DT_STRING)) + payload


@dataclass(frozen=True)
class DescriptorSet:
    """Everything a host can read about one device before talking to its firmware."""

    device: DeviceDescriptor
    configurations: tuple[ConfigurationDescriptor, ...]
    strings: dict[int, str] = field(default_factory=dict)
    langids: tuple[int, ...] = (LANGID_EN_US,)

    def string(self, index: int, langid: int) -> bytes | None:
        """The wire bytes of string ``index`` (index 0 is the LANGID list); None if absent."""
        if index == 0:
            return bytes((2 + 2 * len(self.langids), DT_STRING)) + b"".join(
                struct.pack("<H", lang) for lang in self.langids)
        if langid not in self.langids or index not in self.strings:
            return None
        return string_descriptor(self.strings[index])


def camera_descriptors(serial: str, product: str, firmware_version: str,
                       vendor_id: int = VENDOR_ID, product_id: int = PRODUCT_ID,
                       speed: BusSpeed = SPEEDS["high"]) -> DescriptorSet:
    """The descriptor set of a camera: one configuration, one vendor-specific interface with a
    bulk OUT (commands) and a bulk IN (replies and frames) endpoint; bcdUSB and the bulk packet
    size follow the bus ``speed`` the unit enumerated at."""
    interface = InterfaceDescriptor(endpoints=(EndpointDescriptor(EP_OUT, wMaxPacketSize=speed.max_packet),
                                               EndpointDescriptor(EP_IN, wMaxPacketSize=speed.max_packet)))
    device = DeviceDescriptor(bcdDevice=bcd_version(firmware_version), bcdUSB=speed.bcd_usb,
                              idVendor=vendor_id, idProduct=product_id)
    strings = {1: MANUFACTURER, 2: product, 3: serial, 4: INTERFACE_NAME}
    return DescriptorSet(device, (ConfigurationDescriptor(interfaces=(interface,)),), strings)
