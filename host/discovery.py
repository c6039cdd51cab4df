"""Find cameras: one list over USB (real and simulated), camera serial ports and in-process sims."""
from __future__ import annotations

import logging
from dataclasses import dataclass

import usb.core
import usb.util

from .transports import usb as usb_transport

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DeviceEntry:
    """One camera that can be opened: ``host.open(entry.url)``."""

    url: str
    serial: str | None
    model: str | None
    transport: str  # "usb", "serial" or "sim"
    firmware: str | None = None
    simulated: bool = False
    location: str = ""  # bus/address, port path or process, for humans

    def as_dict(self) -> dict[str, object]:
        return dict(url=self.url, serial=self.serial, model=self.model, transport=self.transport,
                    firmware=self.firmware, simulated=self.simulated, location=self.location)


def _bcd_to_version(bcd: int) -> str:
    """bcdDevice 0xJJMN → "J.M.N"."""
    major = (bcd >> 12) * 10 + ((bcd >> 8) & 0xF)
    return f"{major}.{(bcd >> 4) & 0xF}.{bcd & 0xF}"


def usb_entries() -> list[DeviceEntry]:
    """USB cameras on every bus the USB transport scans (see ``host.transports.usb``)."""
    entries = []
    for kind, dev in usb_transport.find_devices(usb_transport.UsbSelector()):
        try:
            serial = usb_transport.device_string(dev, "serial_number")
            model = usb_transport.device_string(dev, "product")
        finally:
            usb.util.dispose_resources(dev)
        ids = f"{dev.idVendor:04x}:{dev.idProduct:04x}"
        url = f"usb://{ids}?serial={serial}" if serial else f"usb://{ids}"
        if (dev.idVendor, dev.idProduct) == usb_transport.CAMERA_IDS[0] and serial:
            url = f"usb://?serial={serial}"
        entries.append(DeviceEntry(url, serial, model, "usb", _bcd_to_version(dev.bcdDevice),
                                   simulated=kind == "sim",
                                   location=f"{'simulated ' if kind == 'sim' else ''}bus "
                                            f"{dev.bus:03d} address {dev.address:03d}"))
    return entries


def serial_entries() -> list[DeviceEntry]:
    """Serial ports whose USB VID:PID is a camera's (pyserial's port list)."""
    try:
        from serial.tools import list_ports
    except ImportError:  # pyserial is a dependency; tolerate a broken install
        return []
    entries = []
    for port in sorted(list_ports.comports(), key=lambda p: p.device):
        if port.vid is None or (port.vid, port.pid) not in usb_transport.CAMERA_IDS:
            continue
        entries.append(DeviceEntry(port.device, port.serial_number, port.product, "serial",
                                   location=port.location or port.hwid))
    return entries


def inprocess_entries() -> list[DeviceEntry]:
    """Simulators alive in this process and held by no link (``sim://?serial=SN`` opens one).

    Only looked for when ``device_sim`` is already imported: the SDK never imports the simulator.
    """
    import sys

    if "device_sim.registry" not in sys.modules:
        return []
    from device_sim import registry

    return [DeviceEntry(f"sim://?serial={s.serial}", s.serial, s.model, "sim", s.firmware_version, simulated=True,
                        location="this process") for s in registry.live_simulators() if not s.attached]


def list_devices() -> list[DeviceEntry]:
    """Every camera this host can open now: USB, serial ports, in-process simulators."""
    entries: list[DeviceEntry] = []
    for source in (usb_entries, serial_entries, inprocess_entries):
        try:
            entries.extend(source())
        except (usb.core.USBError, OSError) as exc:  # one broken source must not hide the rest
            _log.warning("device discovery via %s failed: %s", source.__name__, exc)
    return entries


__all__ = ["DeviceEntry", "list_devices", "usb_entries", "serial_entries", "inprocess_entries"]
