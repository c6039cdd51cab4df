"""GET_INFO → INFO (SPEC §4.1): who this unit is and what it can do."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from stereocam.protocol import messages as m
from stereocam.protocol.firmware_image import FirmwareBuild
from stereocam.protocol.framing import MAX_PAYLOAD, VERSION_MAJOR, VERSION_MINOR
from stereocam.protocol.params import BY_NAME, defaults

from ..link_layer.dispatcher import Handler
from ..rig.sensor import SENSOR_H, SENSOR_W
from .calibration import CalibrationService

MODEL = "STOC-SIM"
FIRMWARE_VERSION = "1.1.0"
CAPABILITIES = (m.Capability.DISPARITY | m.Capability.SOFTWARE_TRIGGER | m.Capability.EXTERNAL_TRIGGER
                | m.Capability.TIME_SYNC | m.Capability.CALIBRATION | m.Capability.RAW_OUTPUT
                | m.Capability.FRAME_REPAIR | m.Capability.TRIGGER_OUTPUT | m.Capability.SGM
                | m.Capability.POST_PROCESSING)
PROTOCOL_MINOR = VERSION_MINOR  # 1.3: SGM and post-processing capability bits, INFO stage limits (SPEC §4.1, §11.1)
STAGE_LIMITS = ((m.Stage.BLOCK_MATCHING, BY_NAME["width"].hi, BY_NAME["height"].hi),
                (m.Stage.SEMI_GLOBAL, BY_NAME["width"].hi, BY_NAME["height"].hi))
"""Both matchers run at the largest format (SPEC §4.1 stage limits; shown so a host sees the mechanism)."""


def config_limits(build: FirmwareBuild) -> tuple[int, dict[int, tuple[int, int]] | None]:
    """What the booted ``build``'s configuration store enforces: its capabilities as a host
    negotiates them (SPEC §11.2: a 1.2 build has SGM without the bit) and its INFO stage limits."""
    limits = {stage: (w, h) for stage, w, h in STAGE_LIMITS} if build.protocol_minor >= 3 else None
    return m.negotiated_capabilities(build.protocol_minor, build.capabilities), limits
FACTORY_BUILD = FirmwareBuild(FIRMWARE_VERSION, PROTOCOL_MINOR, CAPABILITIES | m.Capability.FIRMWARE_UPDATE, defaults())
"""The build the factory line signs into slot A of a blank unit."""
RECOVERY_BUILD = FirmwareBuild("recovery", PROTOCOL_MINOR, m.Capability.FIRMWARE_UPDATE, {})
"""What the boot stage's recovery reports: it only identifies itself and takes updates."""


@dataclass(frozen=True)
class Identity:
    model: str
    serial: str
    firmware_version: str
    protocol_minor: int = VERSION_MINOR  # the booted build's
    capabilities: int = CAPABILITIES


class InfoHandler:
    def __init__(self, identity: Identity, calibration: CalibrationService, usb_speed: Callable[[], int]):
        self._identity = identity
        self._calibration = calibration
        self._usb_speed = usb_speed  # what the USB controller enumerated at (m.UsbSpeed)

    def handlers(self) -> dict[int, Handler]:
        return {m.MsgType.GET_INFO: self.get_info}

    def get_info(self, _: m.Message) -> m.Info:
        i = self._identity
        return m.Info(i.model, i.serial, i.firmware_version, (VERSION_MAJOR, i.protocol_minor), i.capabilities,
                      SENSOR_W, SENSOR_H, MAX_PAYLOAD, BY_NAME["width"].hi, BY_NAME["height"].hi,
                      self._calibration.calibration_id, self._usb_speed(),
                      STAGE_LIMITS if i.protocol_minor >= 3 else ())
