"""Find cameras: one list over every URL scheme this process knows (see ``stereocam.transports``)."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class DeviceEntry:
    """One camera that can be opened: ``stereocam.open(entry.url)``."""

    url: str
    serial: str | None
    model: str | None
    transport: str  # "usb", "serial", "sim", ...
    firmware: str | None = None
    simulated: bool = False
    location: str = ""  # bus/address, port path or process, for humans

    def as_dict(self) -> dict[str, object]:
        return dict(url=self.url, serial=self.serial, model=self.model, transport=self.transport,
                    firmware=self.firmware, simulated=self.simulated, location=self.location)


def list_devices() -> list[DeviceEntry]:
    """Every camera this host can open now: each scheme module's ``discover()`` (USB buses,
    camera serial ports, and whatever registered schemes add, such as in-process simulators)."""
    from .transports import discover

    return discover()


__all__ = ["DeviceEntry", "list_devices"]
