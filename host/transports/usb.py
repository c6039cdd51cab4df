"""USB transport: a camera's vendor-specific bulk interface, through pyusb.

URLs: ``usb://`` (first camera), ``usb://1209:0001`` (hex VID:PID), ``usb://?serial=SN``, or
both (``usb://1209:0001?serial=SN``). Devices come from the real libusb backend (the library
``libusb-package`` ships, else the system's libusb-1.0) and from every backend registered with
``register_backend`` and from the ``stereocam.usb_backends`` entry points of imported packages
(the simulator declares its simulated bus there; the SDK never imports the simulator).

Reads are bulk IN transfers of ``READ_SIZE`` bytes (a multiple of the 512-byte packet size, so
no packet can overflow the buffer); a transfer ends at the device's short or zero-length packet,
and a zero-length result is not mistaken for data or for the end of the wait. An unplugged
device raises ``DisconnectedError`` as soon as the transfer fails (libusb reports NO_DEVICE at
once; at the latest when the read times out). A stalled endpoint is cleared and retried.
"""
from __future__ import annotations

import array
import errno
import logging
import math
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Iterator
from urllib.parse import parse_qs, urlsplit

import usb.core
import usb.util

from stereocam.protocol.errors import CameraTimeoutError, DisconnectedError, TransportError
from stereocam.protocol.usb_identity import CAMERA_IDS, INTERFACE_CLASS, MAX_PACKET_SIZE_HS

from . import plugins
from .base import Transport

if TYPE_CHECKING:
    from ..discovery import DeviceEntry

_log = logging.getLogger(__name__)

VENDOR_SPECIFIC = INTERFACE_CLASS
MAX_PACKET_SIZE = MAX_PACKET_SIZE_HS
READ_SIZE = 512 * MAX_PACKET_SIZE
"""Bytes per bulk IN transfer: 256 KiB, whole packets."""
POLL_S = 0.1
"""Longest single transfer; longer reads and writes are resubmitted, checking for close()."""
CLOSE_WAIT_S = 2.0
LIBUSB_ERROR_NO_DEVICE = -4
LIBUSB_ERROR_BUSY = -6
LIBUSB_ERROR_PIPE = -9


@dataclass(frozen=True)
class UsbSelector:
    """Which devices a ``usb://`` URL names."""

    ids: tuple[tuple[int, int], ...] = CAMERA_IDS
    serial: str | None = None


def parse_url(url: str) -> UsbSelector:
    """``usb://[VID:PID][?serial=SN]`` → selector; ValueError for anything else."""
    parts = urlsplit(url)
    if parts.scheme != "usb":
        raise ValueError(f"not a usb:// URL: {url!r}")
    ids = CAMERA_IDS
    where = parts.netloc + parts.path.rstrip("/")
    if where:
        try:
            vid, pid = (int(x, 16) for x in where.split(":"))
        except ValueError:
            raise ValueError(f"bad VID:PID {where!r} in {url!r} (want hex, e.g. 1209:0001)") from None
        if not (0 <= vid <= 0xFFFF and 0 <= pid <= 0xFFFF):
            raise ValueError(f"VID:PID out of range in {url!r}")
        ids = ((vid, pid),)
    query = parse_qs(parts.query, keep_blank_values=True)
    unknown = set(query) - {"serial"}
    if unknown:
        raise ValueError(f"unknown option(s) {sorted(unknown)} in {url!r}")
    serial = query["serial"][-1] if "serial" in query else None
    return UsbSelector(ids, serial or None)


# -- finding devices ------------------------------------------------------------------------

_real_backend: object | None = None
_real_backend_loaded = False
_backend_lock = threading.Lock()


def real_backend() -> object | None:
    """The libusb-1.0 backend (``libusb-package``'s library first), or None without libusb."""
    global _real_backend, _real_backend_loaded
    with _backend_lock:
        if not _real_backend_loaded:
            _real_backend_loaded = True
            try:
                import libusb_package
                _real_backend = libusb_package.get_libusb1_backend()
            except ImportError:
                _real_backend = None
            if _real_backend is None:
                import usb.backend.libusb1
                _real_backend = usb.backend.libusb1.get_backend()
        return _real_backend


_extra_backends: dict[str, object] = {}


def register_backend(kind: str, backend: object) -> None:
    """Scan ``backend`` (a ``usb.backend.IBackend``) beside libusb; ``kind`` names it in listings."""
    with _backend_lock:
        _extra_backends[kind] = backend


def backends() -> list[tuple[str, object]]:
    """(kind, backend) for every bus to scan: "libusb" first, then the registered ones, then the
    entry points of imported packages (a registered kind wins over an entry point of that name)."""
    with _backend_lock:
        extra = dict(_extra_backends)
    for kind, ep in plugins.in_use(plugins.USB_BACKENDS).items():
        if kind not in extra:
            extra[kind] = ep.load()()
    found = [("libusb", real_backend()), *extra.items()]
    return [(kind, b) for kind, b in found if b is not None]


def device_string(dev: usb.core.Device, attr: str) -> str | None:
    """A string descriptor, or None when it cannot be read (no permission, no strings)."""
    try:
        return getattr(dev, attr)
    except (usb.core.USBError, ValueError, NotImplementedError):
        return None


def find_devices(selector: UsbSelector) -> Iterator[tuple[str, usb.core.Device]]:
    """Matching devices as (backend kind, pyusb Device), real buses first."""
    for kind, backend in backends():
        try:
            devices = list(usb.core.find(find_all=True, backend=backend))
        except usb.core.USBError as exc:
            _log.warning("cannot enumerate %s USB devices: %s", kind, exc)
            continue
        for dev in devices:
            if (dev.idVendor, dev.idProduct) not in selector.ids:
                continue
            if selector.serial is not None and device_string(dev, "serial_number") != selector.serial:
                usb.util.dispose_resources(dev)
                continue
            yield kind, dev


# -- the transport --------------------------------------------------------------------------

def _is_disconnect(exc: usb.core.USBError) -> bool:
    return exc.errno == errno.ENODEV or exc.backend_error_code == LIBUSB_ERROR_NO_DEVICE


def _is_halt(exc: usb.core.USBError) -> bool:
    return exc.errno == errno.EPIPE or exc.backend_error_code == LIBUSB_ERROR_PIPE


def _bulk_endpoint(intf: usb.core.Interface, direction: int) -> usb.core.Endpoint:
    ep = usb.util.find_descriptor(
        intf, custom_match=lambda e: usb.util.endpoint_direction(e.bEndpointAddress) == direction
        and usb.util.endpoint_type(e.bmAttributes) == usb.util.ENDPOINT_TYPE_BULK)
    if ep is None:
        raise TransportError(f"interface {intf.bInterfaceNumber} has no bulk "
                             f"{'IN' if direction == usb.util.ENDPOINT_IN else 'OUT'} endpoint")
    return ep


class UsbTransport(Transport):
    """Byte pipe over a camera's bulk OUT/IN endpoint pair (interface class 0xFF)."""

    def __init__(self, dev: usb.core.Device, url: str, timeout: float = 1.0) -> None:
        self.url = url
        self.device = dev
        self.timeout = timeout
        self._closed = False
        self._read_lock = threading.Lock()
        self._write_lock = threading.Lock()
        self._rx = array.array("B", bytes(READ_SIZE))
        self._pending = b""
        try:
            self._intf, self._ep_out, self._ep_in = self._claim(dev)
        except usb.core.USBError as exc:
            usb.util.dispose_resources(dev)
            if exc.errno == errno.EBUSY or exc.backend_error_code == LIBUSB_ERROR_BUSY:
                raise TransportError(f"{url}: in use by another host (another program has claimed its "
                                     "interface)") from exc
            if exc.errno == errno.EACCES:
                raise TransportError(f"{url}: no permission to open the USB device "
                                     "(install the udev rule or run as a privileged user)") from exc
            raise self._error(exc, "open") from exc
        except TransportError:
            usb.util.dispose_resources(dev)
            raise

    @staticmethod
    def _claim(dev: usb.core.Device) -> tuple[int, usb.core.Endpoint, usb.core.Endpoint]:
        try:
            cfg = dev.get_active_configuration()
        except usb.core.USBError as exc:  # unconfigured ("Configuration not set")
            if _is_disconnect(exc):
                raise
            dev.set_configuration()
            cfg = dev.get_active_configuration()
        intf = usb.util.find_descriptor(cfg, bInterfaceClass=VENDOR_SPECIFIC)
        if intf is None:
            raise TransportError(f"USB device {dev.idVendor:04x}:{dev.idProduct:04x} has no "
                                 "vendor-specific interface")
        number = intf.bInterfaceNumber
        try:
            if dev.is_kernel_driver_active(number):
                dev.detach_kernel_driver(number)
        except (NotImplementedError, usb.core.USBError):
            pass  # not supported on this OS, or no driver bound
        usb.util.claim_interface(dev, number)
        return (number, _bulk_endpoint(intf, usb.util.ENDPOINT_OUT),
                _bulk_endpoint(intf, usb.util.ENDPOINT_IN))

    def _error(self, exc: usb.core.USBError, action: str) -> TransportError:
        if self._closed:
            return DisconnectedError(f"{self.url} is closed")
        if _is_disconnect(exc):
            return DisconnectedError(f"{self.url}: USB device disconnected ({action})")
        return TransportError(f"{self.url}: USB {action} failed: {exc}")

    def _check_open(self) -> None:
        if self._closed:
            raise DisconnectedError(f"{self.url} is closed")

    def _slice_ms(self, deadline: float) -> int:
        """Milliseconds for the next transfer: at most POLL_S, so close() never waits long."""
        return max(1, math.ceil(min(deadline - time.monotonic(), POLL_S) * 1000))

    def write(self, data: bytes) -> None:
        """Send all of ``data`` as one bulk OUT transfer (more if the device NAKs for long)."""
        self._check_open()
        buf = array.array("B", bytes(data))
        deadline = time.monotonic() + self.timeout
        with self._write_lock:
            sent = 0
            while sent < len(buf):
                self._check_open()
                if time.monotonic() >= deadline:
                    raise CameraTimeoutError(f"{self.url}: device accepted {sent} of {len(buf)} "
                                             f"bytes in {self.timeout:.3g} s")
                chunk = buf if sent == 0 else buf[sent:]
                try:
                    sent += self.device.write(self._ep_out, chunk, self._slice_ms(deadline))
                except usb.core.USBTimeoutError:
                    continue
                except usb.core.USBError as exc:
                    if _is_halt(exc) and not self._closed:
                        self._clear_halt(self._ep_out)
                        continue
                    raise self._error(exc, "write") from exc

    def read(self, max_bytes: int, timeout: float) -> bytes:
        """Up to ``max_bytes`` bytes of the next bulk IN transfer(s); ``b""`` after ``timeout``."""
        self._check_open()
        with self._read_lock:
            if self._pending:
                return self._take(max_bytes)
            deadline = time.monotonic() + max(timeout, 0.0)
            while True:
                self._check_open()
                try:
                    n = self.device.read(self._ep_in, self._rx, self._slice_ms(deadline))
                except usb.core.USBTimeoutError:
                    n = 0
                except usb.core.USBError as exc:
                    if _is_halt(exc) and not self._closed and time.monotonic() < deadline:
                        self._clear_halt(self._ep_in)
                        continue
                    raise self._error(exc, "read") from exc
                if n:
                    self._pending = memoryview(self._rx)[:n].tobytes()
                    return self._take(max_bytes)
                if time.monotonic() >= deadline:  # timed out, or only a zero-length packet
                    return b""

    def _take(self, max_bytes: int) -> bytes:
        data, self._pending = self._pending[:max_bytes], self._pending[max_bytes:]
        return data

    def _clear_halt(self, ep: usb.core.Endpoint) -> None:
        _log.warning("%s: endpoint 0x%02x stalled; clearing the halt", self.url,
                     ep.bEndpointAddress)
        try:
            self.device.clear_halt(ep)
        except usb.core.USBError as exc:
            raise self._error(exc, "clear halt") from exc

    def close(self) -> None:
        """Release the interface and the device handle; idempotent, never raises.

        Waits (at most about POLL_S) for a read or write in another thread to notice: libusb
        must not close a handle with a transfer in flight."""
        if self._closed:
            return
        self._closed = True
        locks = [lock for lock in (self._read_lock, self._write_lock)
                 if lock.acquire(timeout=CLOSE_WAIT_S)]
        try:
            usb.util.release_interface(self.device, self._intf)
        except usb.core.USBError:
            pass
        try:
            usb.util.dispose_resources(self.device)
        except usb.core.USBError:
            pass
        finally:
            for lock in locks:
                lock.release()


def open_transport(url: str, timeout: float = 1.0) -> UsbTransport:
    """Open the first camera ``url`` selects (see the module docstring for the URL forms)."""
    try:
        selector = parse_url(url)
    except ValueError as exc:
        raise TransportError(str(exc)) from exc
    errors: list[str] = []
    for _, dev in find_devices(selector):
        try:
            return UsbTransport(dev, url, timeout)
        except TransportError as exc:
            errors.append(str(exc))
    what = ", ".join(f"{v:04x}:{p:04x}" for v, p in selector.ids)
    if selector.serial:
        what += f" with serial {selector.serial!r}"
    hint = f" ({'; '.join(errors)})" if errors else ""
    if not backends():
        hint += " (no libusb backend: pip install libusb-package)"
    raise TransportError(f"no USB camera {what} could be opened{hint}")


# -- discovery ------------------------------------------------------------------------------

def _bcd_to_version(bcd: int) -> str:
    """bcdDevice 0xJJMN → "J.M.N"."""
    major = (bcd >> 12) * 10 + ((bcd >> 8) & 0xF)
    return f"{major}.{(bcd >> 4) & 0xF}.{bcd & 0xF}"


def discover() -> list["DeviceEntry"]:
    """USB cameras on every bus this module scans (libusb and registered backends)."""
    from ..discovery import DeviceEntry

    entries = []
    for kind, dev in find_devices(UsbSelector()):
        try:
            serial = device_string(dev, "serial_number")
            model = device_string(dev, "product")
        finally:
            usb.util.dispose_resources(dev)
        ids = f"{dev.idVendor:04x}:{dev.idProduct:04x}"
        url = f"usb://{ids}?serial={serial}" if serial else f"usb://{ids}"
        if (dev.idVendor, dev.idProduct) == CAMERA_IDS[0] and serial:
            url = f"usb://?serial={serial}"
        simulated = kind != "libusb"
        entries.append(DeviceEntry(url, serial, model, "usb", _bcd_to_version(dev.bcdDevice),
                                   simulated=simulated,
                                   location=f"{kind + ' ' if simulated else ''}bus "
                                            f"{dev.bus:03d} address {dev.address:03d}"))
    return entries


def reopen_url(url: str, serial: str) -> str:
    """After a replug the bus address changes; the serial does not."""
    return f"usb://?serial={serial}"
