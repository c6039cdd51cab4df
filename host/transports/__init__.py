"""URL → transport: an open table of URL schemes, one module per scheme (like pyserial's
``serial_for_url`` and its ``protocol_handler_packages``).

A scheme module provides ``open_transport(url, timeout) -> Transport`` and may provide
``discover() -> list[DeviceEntry]`` (cameras it can open now) and ``reopen_url(url, serial) -> str``
(the URL that finds the same unit again after an unplug or a reboot).

Schemes come from three places, first match wins: ``register_scheme`` calls, the built-in table
``SCHEMES``, and the ``stereocam.url_schemes`` entry-point group (``plugins``: the simulator declares
``sim://`` and ``replay://`` there, so ``stereocam.open("sim://")`` works in a fresh process and the
SDK never imports the simulator by name). Discovery asks the table's modules and the entry-point
schemes whose package is already imported. Anything else (a device path, ``socket://``,
``rfc2217://``, ``loop://``) goes to pyserial.
"""
from __future__ import annotations

import importlib
import importlib.util
import logging
import pkgutil
import threading
from types import ModuleType
from typing import TYPE_CHECKING
from urllib.parse import SplitResult, urlsplit

from ..protocol.errors import ConfigError, StereoCamError
from . import plugins
from .base import Transport

if TYPE_CHECKING:
    from ..discovery import DeviceEntry

ENTRY_POINT_GROUP = plugins.URL_SCHEMES
SERIAL_MODULE = "stereocam.transports.serial_port"
SCHEMES: dict[str, str] = {"usb": "stereocam.transports.usb"}
"""scheme → module name; ``register_scheme`` adds to it."""
_lock = threading.Lock()
_log = logging.getLogger(__name__)


def register_scheme(scheme: str, module: str) -> None:
    """Route ``scheme://`` URLs to ``module`` (imported on first use)."""
    with _lock:
        SCHEMES[scheme.lower()] = module


def split_url(url: str) -> SplitResult:
    """``url``'s parts; ConfigError naming it if it does not parse (an unclosed IPv6 bracket, a
    bracketed host that is no address, characters the parser refuses)."""
    try:
        return urlsplit(url)
    except ValueError as exc:
        raise ConfigError(f"{url!r} is not a valid camera URL: {exc}") from exc


def scheme_of(url: str) -> str:
    return split_url(url).scheme.lower() if "://" in url else ""


def scheme_module(url: str) -> ModuleType:
    """The module that handles ``url``'s scheme (pyserial's for anything not in the table)."""
    scheme = scheme_of(url)
    with _lock:
        name = SCHEMES.get(scheme)
    if name is None and scheme in (declared := plugins.declared(ENTRY_POINT_GROUP)):
        name = declared[scheme].module
    return importlib.import_module(name or SERIAL_MODULE)


def open_transport(url: str, timeout: float = 1.0) -> Transport:
    """Open the transport that ``url`` names."""
    if not isinstance(url, str) or not url:
        raise ConfigError(f"a camera URL must be a non-empty string, got {url!r}")
    split_url(url)
    module = scheme_module(url)
    scheme = scheme_of(url)
    if scheme and module.__name__ == SERIAL_MODULE and not (scheme.isascii() and scheme.isidentifier() and (
            importlib.util.find_spec(f"serial.urlhandler.protocol_{scheme}") is not None)):  # pyserial: "not known"
        raise ConfigError(f"{url!r}: no transport for {scheme}://; known: {', '.join(known_schemes())}, "
                          f"or a serial device path (a TCP camera: socket://HOST:PORT)")
    try:
        return module.open_transport(url, timeout)
    except StereoCamError:
        raise
    except ValueError as exc:  # a scheme module's parsing (UnicodeError included): typed, naming the URL
        raise ConfigError(f"{url!r} is not a valid camera URL: {type(exc).__name__}: {exc}") from exc


def known_schemes() -> list[str]:
    """Every scheme ``open_transport`` routes: the table's, the entry points', pyserial's URL handlers."""
    import serial.urlhandler
    with _lock:
        ours = [*SCHEMES]
    theirs = [m.name.removeprefix("protocol_") for m in pkgutil.iter_modules(serial.urlhandler.__path__)
              if m.name.startswith("protocol_")]
    return sorted({*ours, *plugins.declared(ENTRY_POINT_GROUP), *theirs})


def reopen_url(url: str, serial: str) -> str:
    """The URL that finds the unit with ``serial`` again (USB by serial: bus addresses change)."""
    module = scheme_module(url)
    reopen = getattr(module, "reopen_url", None)
    return reopen(url, serial) if reopen is not None else url


def discover() -> list["DeviceEntry"]:
    """Cameras every loaded scheme module can open now; one failing source does not hide the rest."""
    with _lock:
        table = [*SCHEMES.values(), SERIAL_MODULE]
    in_use = [ep.module for ep in plugins.in_use(ENTRY_POINT_GROUP).values()]
    names = list(dict.fromkeys([*table, *in_use]))
    entries: list[DeviceEntry] = []
    for name in names:
        module = importlib.import_module(name)
        find = getattr(module, "discover", None)
        if find is None:
            continue
        try:
            entries.extend(find())
        except Exception as exc:  # discovery must survive a broken bus or driver
            _log.warning("device discovery via %s failed: %s", name, exc)
    return entries


__all__ = ["Transport", "open_transport", "register_scheme", "scheme_module", "reopen_url", "discover",
           "SCHEMES", "ENTRY_POINT_GROUP"]
