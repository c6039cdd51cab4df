"""The one exception tree of the stack, shared by host, device simulator and tools."""
from __future__ import annotations

import enum


class StereoCamError(Exception):
    """Root of every error this stack raises on purpose."""


class ProtocolError(StereoCamError):
    """Bytes that do not form a valid message (bad payload layout, wrong reply type, ...)."""


class VersionMismatchError(ProtocolError):
    """The peer speaks a protocol major version this code does not implement."""


class ErrorCode(enum.IntEnum):
    """Error codes carried by a NACK (protocol/SPEC.md, "Error codes")."""

    UNKNOWN_TYPE = 1
    BAD_PAYLOAD = 2
    UNKNOWN_PARAM = 3
    OUT_OF_RANGE = 4
    BAD_STATE = 5
    BUSY = 6
    INTERNAL = 7
    UNSUPPORTED_VERSION = 8
    STORAGE = 9  # flash write or verify failed; the previous stored data is still in force
    IMAGE_REJECTED = 10  # since 1.2: a firmware image refused; the text starts with the reason (SPEC §13.4)


class DeviceError(StereoCamError):
    """The device refused a command (NACK). Carries the device's code, parameter and text."""

    def __init__(self, code: int, message: str, param: str | None = None, request_type: int = 0):
        try:
            self.code: ErrorCode | int = ErrorCode(code)
        except ValueError:
            self.code = code
        self.param = param
        self.device_message = message
        self.request_type = request_type
        name = self.code.name if isinstance(self.code, ErrorCode) else f"code {code}"
        where = f" [{param}]" if param else ""
        super().__init__(f"device refused request 0x{request_type:04x}: {name}{where}: {message}")


class ConfigError(StereoCamError, ValueError):
    """A configuration request that cannot be expressed (unknown parameter name, wrong type)."""


class ConfigRefused(DeviceError, ConfigError):
    """The device refused a configuration (its NACK of SET_CONFIG: an unknown parameter, a value out
    of range, one that cannot change while streaming): a DeviceError with the device's code, parameter
    and text, and a ConfigError, as ``Camera.check_config``'s verdict on the same values is."""


CONFIG_REFUSALS = frozenset({ErrorCode.UNKNOWN_PARAM, ErrorCode.OUT_OF_RANGE, ErrorCode.BAD_STATE})
"""The NACK codes of SET_CONFIG that say the configuration itself was refused (ConfigRefused)."""


class TransportError(StereoCamError):
    """The link to the device failed (I/O error, cannot open)."""


class DisconnectedError(TransportError):
    """The device went away (cable pulled, process ended, socket closed)."""


class LinkFailedError(DisconnectedError):
    """The host's link ended because its reader or event path failed (the cause is chained)."""


class StreamStoppedError(StereoCamError):
    """The device stopped a stream the host had started (watchdog) and restarting it failed."""


class VerificationError(StereoCamError):
    """Data read back from the device differs from what was written."""


class CameraTimeoutError(StereoCamError, TimeoutError):
    """No answer or frame within the deadline; also a builtin TimeoutError."""


class StreamStalledError(CameraTimeoutError):
    """Streaming, but no frame came within the deadline (iteration raises this instead of ending)."""


class SilentHeadsError(StereoCamError):
    """Cameras of a group that see no trigger pulses while the others stream (an unwired head, a
    cable out); ``heads`` names them."""

    def __init__(self, message: str, heads: tuple[str, ...] = ()):
        super().__init__(message)
        self.heads = heads


class EndOfRecordingError(StereoCamError):
    """A replayed recording has delivered its last frame (``replay://``); ``path`` names the file."""

    def __init__(self, message: str, path: str = ""):
        super().__init__(message)
        self.path = path


class MissingPlaneError(StereoCamError, ValueError):
    """A frame lacks the plane an operation needs (depth without a disparity plane: outputs
    excluded it, or the frame is raw); also a ValueError."""


class CallbackError(StereoCamError):
    """A frame callback raised; the callback's own exception is the ``__cause__``."""


class InputFileError(StereoCamError):
    """An input file that is refused before it is read: not a regular file, or larger than it may be."""


class MissingInputError(InputFileError):
    """An input file that does not exist: the caller's mistake (the tools exit 2, bad usage)."""
class MissingExtraError(StereoCamError, ImportError):
    """A feature needs a third-party package of an optional install group (a pip extra) that is not
    installed; the message names the extra. Also an ImportError."""
