"""URL → transport: an open table of URL schemes, one module per scheme (like pyserial's
``serial_for_url`` and its ``protocol_handler_packages``).

A scheme module provides ``open_transport(url, timeout) -> Transport`` and may provide
``discover() -> list[DeviceEntry]`` (cameras it can open now) and ``reopen_url(url, serial) -> str``
(the URL that finds the same unit again after an unplug or a reboot).

Schemes come from three places, first match wins: ``register_scheme`` calls (a package that
adds a scheme calls it when imported: the simulator registers ``sim://`` and its USB bus this
way), the built-in table ``SCHEMES``, and the ``stereocam.url_schemes`` entry-point group (so
``stereocam.open("sim://")`` works in a fresh process without importing the simulator first).
Anything else (a device path, ``socket://``, ``rfc2217://``, ``loop://``) goes to pyserial.
"""
from __future__ import annotations

import importlib
import logging
import threading
from importlib.metadata import entry_points
from types import ModuleType
from typing import TYPE_CHECKING
from urllib.parse import SplitResult, urlsplit

from ..protocol.errors import ConfigError, StereoCamError, TransportError
from .base import Transport

if TYPE_CHECKING:
    from ..discovery import DeviceEntry

ENTRY_POINT_GROUP = "stereocam.url_schemes"
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


def _entry_point(scheme: str) -> str | None:
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name == scheme:
            return ep.value
    return None


def scheme_module(url: str) -> ModuleType:
    """The module that handles ``url``'s scheme (pyserial's for anything not in the table)."""
    scheme = scheme_of(url)
    with _lock:
        name = SCHEMES.get(scheme)
    if name is None and scheme:
        name = _entry_point(scheme)
    return importlib.import_module(name or SERIAL_MODULE)


def open_transport(url: str, timeout: float = 1.0) -> Transport:
    """Open the transport that ``url`` names."""
    if not isinstance(url, str) or not url:
        raise TransportError(f"a camera URL must be a non-empty string, got {url!r}")
    split_url(url)
    module = scheme_module(url)
    try:
        return module.open_transport(url, timeout)
    except StereoCamError:
        raise
    except ValueError as exc:  # a scheme module's parsing (UnicodeError included): typed, naming the URL
        raise ConfigError(f"{url!r} is not a valid camera URL: {type(exc).__name__}: {exc}") from exc


def reopen_url(url: str, serial: str) -> str:
    """The URL that finds the unit with ``serial`` again (USB by serial: bus addresses change)."""
    module = scheme_module(url)
    reopen = getattr(module, "reopen_url", None)
    return reopen(url, serial) if reopen is not None else url


def discover() -> list["DeviceEntry"]:
    """Cameras every loaded scheme module can open now; one failing source does not hide the rest."""
    with _lock:
        names = list(dict.fromkeys([*SCHEMES.values(), SERIAL_MODULE]))
    entries: list[DeviceEntry] = []
    for name in names:
        module = importlib.import_module(name)
        find = getattr(module, "discover", None)
        if find is None:
            continue
        try:
            entries.extend(find())
        except Exception as exc:  # noqa: BLE001 - discovery must survive a broken bus or driver
            _log.warning("device discovery via %s failed: %s", name, exc)
    return entries


__all__ = ["Transport", "open_transport", "register_scheme", "scheme_module", "reopen_url", "discover",
           "SCHEMES", "ENTRY_POINT_GROUP"]
