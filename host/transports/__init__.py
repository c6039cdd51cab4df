"""URL → transport, one small module per scheme (like pyserial's ``serial_for_url``).

Schemes listed in ``SCHEMES`` go to their module's ``open_transport(url, timeout)``;
anything else (a device path, ``socket://``, ``rfc2217://``, ``loop://``) goes to pyserial.
"""
from __future__ import annotations

import importlib
from urllib.parse import urlsplit

from .base import Transport

SCHEMES: dict[str, str] = {
    "sim": "host.transports.inprocess",
    "usb": "host.transports.usb",
}
SERIAL_MODULE = "host.transports.serial_port"


def open_transport(url: str, timeout: float = 1.0) -> Transport:
    """Open the transport that ``url`` names."""
    scheme = urlsplit(url).scheme if "://" in url else ""
    module = importlib.import_module(SCHEMES.get(scheme, SERIAL_MODULE))
    return module.open_transport(url, timeout)


__all__ = ["Transport", "open_transport", "SCHEMES"]
