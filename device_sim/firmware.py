"""The simulated firmware, assembled: a STOC-class unit (sensor rig + firmware) as one object.

The parts mirror the host SDK's: the link layer (link_layer/: decoder, replay cache, refusals
as NACKs, the sink), the command handlers (handlers/) and the capture pipeline (pipeline/: when
to expose, then render, rectify, match, segment). This module only wires them together and keeps
the simulator's own controls (scene, ground truth), which never travel on the wire.
"""
from __future__ import annotations

import collections
import tempfile
from pathlib import Path

from stereocam.protocol import messages as m
from stereocam.protocol.calibration import StereoCalibration

from . import registry
from .calibration.truth import true_calibration
from .clock import DeviceClock
from .ground_truth import GroundTruth, TruthLog
from .handlers.calibration import CalibrationService
from .handlers.config import ConfigHandlers
from .handlers.config_store import ConfigStore
from .handlers.device_info import FIRMWARE_VERSION, MODEL, Identity, InfoHandler
from .handlers.heartbeat import HeartbeatHandlers
from .handlers.streaming import StreamingHandlers
from .link_layer.device_link import DeviceLink, Sink
from .link_layer.dispatcher import Dispatcher
from .pipeline.capture_engine import CaptureEngine, CaptureRequest
from .pipeline.capture_pipeline import CapturePipeline
from .rig.scene import Scene
from .rig.sensor import SensorRig
from .trigger import TriggerLine


class SimulatedCamera:
    """One simulated STOC-class unit (firmware + sensor rig)."""

    def __init__(self, serial: str | None = None, seed: int = 0, trigger_line: TriggerLine | None = None,
                 flash_path: str | Path | None = None, factory_calibrated: bool = True,
                 scene: Scene | str = Scene.LAB):
        """``scene``: what the rig looks at ("lab", "wall", "board"; a simulator setting, changeable
        at run time through ``scene``, never a device parameter). ``flash_path``: the file behind
        this unit's flash (kept across runs); None: a private temporary file. ``factory_calibrated``:
        the unit left the factory with its true calibration stored (False: fresh from assembly,
        streams raw images until calibrated)."""
        self.seed = seed
        self.serial = serial or f"SIM{seed:05d}"
        self.model = MODEL
        self.firmware_version = FIRMWARE_VERSION
        self.clock = DeviceClock(seed)
        self.config = ConfigStore()
        self.counters: collections.Counter[str] = collections.Counter()
        self.usb_speed = m.UsbSpeed.NOT_USB  # set by the simulated USB bus while plugged (INFO reports it)
        self._truth_cal = true_calibration(seed)
        self.rig = SensorRig(seed, self._truth_cal)
        self._tmpdir = None
        if flash_path is None:
            self._tmpdir = tempfile.TemporaryDirectory(prefix="stereocam-flash-")
            flash_path = Path(self._tmpdir.name) / f"{self.serial}.flash"
        self.calibration = CalibrationService(flash_path, self._truth_cal, factory_calibrated)
        self.truth = TruthLog(self.rig)

        # the engine's callbacks reach the pipeline and the watchdog, which themselves need the engine
        self.dispatcher = Dispatcher(self.counters)
        self.engine = CaptureEngine(lambda req: self.pipeline.produce(req), lambda: self.heartbeat.watchdog())
        self.link = DeviceLink(self.dispatcher, on_lost=self.engine.stop)
        self.pipeline = CapturePipeline(seed, self.rig, self.config, self.calibration, self.clock, self.truth,
                                        self._send_capture_part, self.counters, self.engine.count_drop)
        self.scene = scene
        self.heartbeat = HeartbeatHandlers(self.clock, self.config, self.engine, self.link, self.counters)
        self.streaming = StreamingHandlers(self.config, self.engine, self.counters)
        for group in (InfoHandler(Identity(self.model, self.serial, self.firmware_version), self.calibration,
                                  lambda: self.usb_speed),
                      ConfigHandlers(self.config, self.engine), self.streaming, self.heartbeat, self.calibration):
            self.dispatcher.register(group.handlers())
        self.trigger_line = trigger_line
        if trigger_line is not None:
            trigger_line.attach(self.streaming.on_pulse)
        self.pipeline.warm_up()
        registry.register(self)

    # -- the host link ------------------------------------------------------------------------
    def attach(self, sink: Sink) -> None:
        """Send all further output to ``sink`` (a new host link)."""
        self.link.attach(sink)

    @property
    def attached(self) -> bool:
        """Whether a host link (in-process pipe, pty, socket, USB) currently holds this unit."""
        return self.link.attached

    def detach(self) -> None:
        """The host link is gone: output is discarded and streaming stops."""
        self.link.detach()

    def receive(self, data: bytes) -> None:
        """Bytes from the host; replies go to the sink before this returns."""
        self.link.receive(data)

    def _send_capture_part(self, req: CaptureRequest, wire: bytes) -> bool:
        """A capture whose stream was stopped meanwhile is cut off (the host counts it incomplete)."""
        return self.link.send(wire, lambda: self.engine.current(req))

    # -- simulator controls (never on the wire) ---------------------------------------------------
    @property
    def scene(self) -> Scene:
        """What the rig looks at; set it (a Scene or its name) to change the view from the next capture."""
        return self.pipeline.scene

    @scene.setter
    def scene(self, value: Scene | str) -> None:
        self.pipeline.scene = Scene.parse(value)

    def ground_truth(self, sequence: int) -> GroundTruth | None:
        """Truth for one of the last few captures (None once it has aged out)."""
        return self.truth.ground_truth(sequence)

    def true_calibration(self) -> StereoCalibration:
        """This unit's true calibration (full sensor resolution), as the calibration tool writes it."""
        return self._truth_cal

    def status_counters(self) -> dict[str, int]:
        """The counters a STATUS reply carries."""
        return self.heartbeat.status_counters()

    # -- lifetime -------------------------------------------------------------------------------
    def close(self) -> None:
        registry.unregister(self)
        self.engine.close()
        self.pipeline.close()
        if self.trigger_line is not None:
            self.trigger_line.detach(self.streaming.on_pulse)
        self.link.close()
        if self._tmpdir is not None:
            self._tmpdir.cleanup()

    def __enter__(self) -> "SimulatedCamera":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
