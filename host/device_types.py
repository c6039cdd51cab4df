"""What a camera reports about itself: identity (INFO), state (STATUS), configuration by name."""
from __future__ import annotations

from dataclasses import dataclass, fields

from stereocam.protocol import messages as m
from stereocam.protocol.params import BY_ID, TriggerMode


@dataclass(frozen=True)
class DeviceInfo(m.Info):
    """The device's INFO reply as the SDK hands it out: every field of the message (protocol/messages.py),
    ``calibration_id`` being the calibration in force when it was read (0 = uncalibrated)."""

    @classmethod
    def from_message(cls, info: m.Info) -> "DeviceInfo":
        return cls(**{f.name: getattr(info, f.name) for f in fields(info)})


@dataclass(frozen=True)
class DeviceStatus:
    uptime_us: int
    streaming: bool
    trigger_mode: TriggerMode
    counters: dict[str, int]


def config_names(values: dict[int, int]) -> dict[str, int]:
    """A CONFIG / CONFIG_APPLIED parameter list by name (``param_<id>`` for ids the table lacks)."""
    return {BY_ID[k].name if k in BY_ID else f"param_{k}": v for k, v in values.items()}
