"""Plug-ins found through entry points: URL schemes (``stereocam.url_schemes``) and USB buses
(``stereocam.usb_backends``) that another package declares, so the SDK never imports it by name.

Opening a URL loads its scheme's plug-in; listing devices only asks the plug-ins whose package this
process has already imported (a simulator that was never imported has no devices to list).
"""
from __future__ import annotations

import sys
from importlib.metadata import EntryPoint, entry_points

URL_SCHEMES = "stereocam.url_schemes"
"""scheme name -> module with ``open_transport`` (and maybe ``discover``, ``reopen_url``)"""
USB_BACKENDS = "stereocam.usb_backends"
"""bus kind -> a callable returning a ``usb.backend.IBackend`` to scan beside libusb"""
SDK_ROOT = "stereocam"


def provider(module: str) -> str:
    """The package that ships ``module``: its top-level package (``acme.links.scheme`` -> ``acme``), or
    for a module beneath this distribution's root its subpackage (``stereocam.pkg.links.x`` -> ``stereocam.pkg``)."""
    parts = module.split(".")
    return ".".join(parts[:2] if parts[0] == SDK_ROOT and len(parts) > 2 else parts[:1])


def declared(group: str) -> dict[str, EntryPoint]:
    """name -> entry point of ``group``, as installed distributions declare them."""
    return {ep.name: ep for ep in entry_points(group=group)}


def in_use(group: str) -> dict[str, EntryPoint]:
    """The entry points of ``group`` whose providing package is already imported in this process."""
    return {name: ep for name, ep in declared(group).items() if provider(ep.module) in sys.modules}
