"""The errors the simulated bus raises: exactly the pyusb exceptions the libusb1 backend raises.

A driver written against real hardware checks ``e.errno`` (``errno.ENODEV``, ``ETIMEDOUT``, ...)
or ``e.backend_error_code`` (``LIBUSB_ERROR_NO_DEVICE``, ...); both are set the way
``usb.backend.libusb1`` sets them, so the same driver code works on the simulated bus.
"""
from __future__ import annotations

import enum
import errno

from usb.core import USBError, USBTimeoutError


class LibusbError(enum.IntEnum):
    """libusb_error codes (libusb.h)."""

    IO = -1
    INVALID_PARAM = -2
    ACCESS = -3
    NO_DEVICE = -4
    NOT_FOUND = -5
    BUSY = -6
    TIMEOUT = -7
    OVERFLOW = -8
    PIPE = -9
    INTERRUPTED = -10
    NO_MEM = -11
    NOT_SUPPORTED = -12


_MESSAGES = {
    LibusbError.IO: ("Input/output error", errno.EIO),
    LibusbError.INVALID_PARAM: ("Invalid parameter", errno.EINVAL),
    LibusbError.ACCESS: ("Access denied (insufficient permissions)", errno.EACCES),
    LibusbError.NO_DEVICE: ("No such device (it may have been disconnected)", errno.ENODEV),
    LibusbError.NOT_FOUND: ("Entity not found", errno.ENOENT),
    LibusbError.BUSY: ("Resource busy", errno.EBUSY),
    LibusbError.TIMEOUT: ("Operation timed out", errno.ETIMEDOUT),
    LibusbError.OVERFLOW: ("Overflow", errno.EOVERFLOW),
    LibusbError.PIPE: ("Pipe error", errno.EPIPE),
    LibusbError.INTERRUPTED: ("System call interrupted (perhaps due to signal)", errno.EINTR),
    LibusbError.NO_MEM: ("Insufficient memory", errno.ENOMEM),
    LibusbError.NOT_SUPPORTED: ("Operation not supported or unimplemented on this platform",
                                errno.ENOSYS),
}


def usb_error(code: LibusbError, detail: str = "") -> USBError:
    """The pyusb exception libusb1's backend raises for ``code`` (timeouts: USBTimeoutError)."""
    text, err = _MESSAGES[code]
    if detail:
        text = f"{text} [{detail}]"
    cls = USBTimeoutError if code is LibusbError.TIMEOUT else USBError
    return cls(text, int(code), err)
