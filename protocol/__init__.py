"""Protocol v1: framing, typed messages, the parameter table and the error tree (no I/O)."""
from . import messages, params
from .errors import (CameraTimeoutError, ConfigError, DeviceError, DisconnectedError, ErrorCode, ProtocolError,
                     StereoCamError, TransportError, VersionMismatchError)
from .framing import MAX_PAYLOAD, Decoder, DecoderStats, Packet, encode_frame

__all__ = [
    "messages", "params", "Decoder", "DecoderStats", "Packet", "encode_frame", "MAX_PAYLOAD",
    "StereoCamError", "ProtocolError", "VersionMismatchError", "DeviceError", "ConfigError", "ErrorCode",
    "TransportError", "DisconnectedError", "CameraTimeoutError",
]
