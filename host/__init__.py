"""stereocam: the host SDK for STOC-class stereo cameras. ``stereocam.open(url)`` gives a Camera.

Beneath it: ``stereocam.protocol`` (the wire protocol, no I/O), ``stereocam.transports`` (one
module per URL scheme), the simulated camera (a subpackage the SDK never imports) and ``stereocam.tools``
(the ``stereocam`` command).
"""
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _version

from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.errors import (CallbackError, CameraTimeoutError, ConfigError, DeviceError,
                                      DisconnectedError, ErrorCode, LinkFailedError, MissingPlaneError, ProtocolError,
                                      StereoCamError, StreamStalledError, StreamStoppedError, TransportError,
                                      VerificationError, VersionMismatchError)
from stereocam.protocol.params import Output, TriggerMode

from .calibration_io import StoredCalibration
from .camera import Camera, DeviceInfo, DeviceStatus, open
from .discovery import DeviceEntry, list_devices
from .frames import DisparityFormat, Frame, FrameStatus, StereoGeometry
from .group import CameraGroup  # noqa: F401  (several cameras on one trigger line)
from .pointcloud import write_ply

try:
    __version__ = _version("stereocam")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"

__all__ = [
    "__version__",
    "open", "list_devices", "DeviceEntry", "Camera", "DeviceInfo", "DeviceStatus", "Frame", "FrameStatus",
    "DisparityFormat", "StereoGeometry", "StereoCalibration", "StoredCalibration", "TriggerMode", "Output",
    "write_ply", "StereoCamError", "ProtocolError", "VersionMismatchError", "DeviceError", "ConfigError",
    "ErrorCode", "TransportError", "DisconnectedError", "LinkFailedError", "StreamStoppedError", "CameraTimeoutError",
    "VerificationError", "StreamStalledError", "CallbackError", "MissingPlaneError",
]
