"""stereocam: the host SDK for STOC-class stereo cameras. ``stereocam.open(url)`` gives a Camera.

Beneath it: ``stereocam.protocol`` (the wire protocol, no I/O), ``stereocam.transports`` (one
module per URL scheme), the simulated camera (a subpackage the SDK never imports) and ``stereocam.tools``
(the ``stereocam`` command).

Importing this package loads nothing: each public name is imported on first use (PEP 562), so
``import stereocam.protocol`` pulls in no SDK module.
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from stereocam.protocol.calibration import StereoCalibration
    from stereocam.protocol.errors import (CallbackError, CameraTimeoutError, ConfigError, ConfigRefused, DeviceError,
                                          DisconnectedError, ErrorCode, LinkFailedError, MissingPlaneError,
                                          ProtocolError, StereoCamError, StreamStalledError, StreamStoppedError,
                                          TransportError, VerificationError, VersionMismatchError,
                                          SilentHeadsError, EndOfRecordingError)
    from stereocam.protocol.params import Output, TriggerMode

    from .calibration_io import StoredCalibration
    from .camera import Camera, DeviceInfo, DeviceStatus, open
    from .discovery import DeviceEntry, list_devices
    from .frames import DisparityFormat, Frame, FrameStatus, StereoGeometry
    from .group import CameraGroup
    from .pointcloud import write_ply

_ERRORS = ("StereoCamError", "ProtocolError", "VersionMismatchError", "DeviceError", "ConfigError", "ConfigRefused",
           "ErrorCode", "TransportError", "DisconnectedError", "LinkFailedError", "StreamStoppedError",
           "CameraTimeoutError", "VerificationError", "StreamStalledError", "CallbackError", "MissingPlaneError",
           "SilentHeadsError", "EndOfRecordingError")
_EXPORTS: dict[str, str] = {
    **dict.fromkeys(_ERRORS, "stereocam.protocol.errors"),
    "StereoCalibration": "stereocam.protocol.calibration",
    "Output": "stereocam.protocol.params", "TriggerMode": "stereocam.protocol.params",
    "StoredCalibration": "stereocam.calibration_io",
    "Camera": "stereocam.camera", "DeviceInfo": "stereocam.camera", "DeviceStatus": "stereocam.camera",
    "open": "stereocam.camera",
    "DeviceEntry": "stereocam.discovery", "list_devices": "stereocam.discovery",
    "DisparityFormat": "stereocam.frames", "Frame": "stereocam.frames", "FrameStatus": "stereocam.frames",
    "StereoGeometry": "stereocam.frames",
    "CameraGroup": "stereocam.group",  # several cameras on one trigger line
    "write_ply": "stereocam.pointcloud",
}
"""public name -> the module that defines it"""

__all__ = [
    "__version__",
    "open", "list_devices", "DeviceEntry", "Camera", "CameraGroup", "DeviceInfo", "DeviceStatus", "Frame",
    "FrameStatus", "DisparityFormat", "StereoGeometry", "StereoCalibration", "StoredCalibration", "TriggerMode",
    "Output", "write_ply", "StereoCamError", "ProtocolError", "VersionMismatchError", "DeviceError", "ConfigError",
    "ConfigRefused", "ErrorCode", "TransportError", "DisconnectedError", "LinkFailedError", "StreamStoppedError",
    "CameraTimeoutError",
    "VerificationError", "StreamStalledError", "CallbackError", "MissingPlaneError", "SilentHeadsError",
    "EndOfRecordingError",
]


def _installed_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("stereocam")
    except PackageNotFoundError:  # running from a source tree that was never installed
        return "0+unknown"


def __getattr__(name: str) -> Any:
    """Import a public name's module (or a submodule) on first use and keep the name here."""
    if name == "__version__":
        value: Any = _installed_version()
    elif name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name]), name)
    else:  # a submodule, as ``stereocam.transports`` was reachable when this package imported it eagerly
        try:
            value = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS, "__version__"})
