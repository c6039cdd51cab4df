"""What a camera reports about itself: identity (INFO), state (STATUS), configuration by name."""
from __future__ import annotations

from dataclasses import dataclass

from stereocam.protocol.params import BY_ID, TriggerMode


@dataclass(frozen=True)
class DeviceInfo:
    model: str
    serial: str
    firmware_version: str
    protocol_version: tuple[int, int]
    capabilities: int
    sensor_width: int
    sensor_height: int
    max_payload: int
    calibration_id: int  # the calibration in force when this was read; 0 = uncalibrated
    max_width: int = 0  # largest frame width the device may send (INFO)
    max_height: int = 0


@dataclass(frozen=True)
class DeviceStatus:
    uptime_us: int
    streaming: bool
    trigger_mode: TriggerMode
    counters: dict[str, int]


def config_names(values: dict[int, int]) -> dict[str, int]:
    """A CONFIG / CONFIG_APPLIED parameter list by name (``param_<id>`` for ids the table lacks)."""
    return {BY_ID[k].name if k in BY_ID else f"param_{k}": v for k, v in values.items()}
