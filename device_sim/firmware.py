"""The simulated firmware, assembled: a STOC-class unit (sensor rig + firmware) as one object.

The parts mirror the host SDK's: the link layer (link_layer/: decoder, replay cache, refusals
as NACKs, the sink), the command handlers (handlers/) and the capture pipeline (pipeline/: when
to expose, then render, rectify, match, segment). This module only wires them together and keeps
the simulator's own controls (scene, ground truth), which never travel on the wire.
"""
from __future__ import annotations

import collections
import logging
import threading
from pathlib import Path
from typing import Callable

from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

from stereocam.protocol import messages as m
from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.params import BY_NAME

from . import registry
from .boot.boot_stage import Booted, BootStage
from .boot.boot_state import BootStateStore
from .boot.factory import DEV_SIGNING_KEY, provision, trusted_key
from .boot.layout import FLASH_SIZE, FlashLayout
from .boot.slots import Slots
from .boot.update_service import UpdateService
from .calibration.flash import NorFlash, PowerLossError
from .clock import REAL_CLOCK, Clock, DeviceClock, UnitClock
from .ground_truth import GroundTruth, TruthLog
from .handlers.calibration import CalibrationService
from .handlers.config import ConfigHandlers
from .handlers.config_store import ConfigStore
from .handlers.device_info import FACTORY_BUILD, MODEL, RECOVERY_BUILD, Identity, InfoHandler, config_limits
from .handlers.frame_repair import FrameRepair
from .handlers.heartbeat import HeartbeatHandlers
from .handlers.streaming import StreamingHandlers
from .handlers.update import UpdateHandlers
from .link_layer.device_link import DeviceLink, HangUp, Sink
from .link_layer.dispatcher import Dispatcher
from .link_layer.refusal import Refusal
from .pipeline.capture_engine import CaptureEngine, CaptureRequest
from .pipeline.capture_pipeline import CapturePipeline
from .replay import ReplayEngine, ReplaySource
from .rig.scene import Scene
from .rig.sensor import SensorRig
from .scratch_flash import ScratchFlash
from .rig.lens import LensClass, lens_calibration
from .trigger import Line, TriggerInput, TriggerLine, TriggerOutput
from .watchdog import WatchdogThread

_log = logging.getLogger(__name__)


class SimulatedCamera:
    """One simulated STOC-class unit (firmware + sensor rig)."""

    def __init__(self, serial: str | None = None, seed: int = 0, trigger_line: Line | None = None,
                 flash_path: str | Path | None = None, factory_calibrated: bool = True,
                 scene: Scene | str = Scene.LAB, vendor_key: Ed25519PrivateKey = DEV_SIGNING_KEY,
                 flash_size: int = FLASH_SIZE, source: ReplaySource | None = None, timebase: Clock | None = None,
                 lens: LensClass | str = LensClass.STANDARD):
        """``lens``: the lens class ("standard", "wide", "fisheye"; rig/lens.py): the rig renders
        through it and the factory flash holds its true calibration. ``scene``: what the rig looks at
        ("lab", "wall", "board", a scene class; a simulator setting, never a device parameter).
        ``flash_path``: the file behind the flash (kept across runs); None: a private file removed at
        close (scratch_flash.py). ``factory_calibrated``: the unit left the factory with its true
        calibration stored (False: streams raw images until calibrated). ``vendor_key``: the signing
        key whose public half the factory provisions. ``source``: a recording that stands in for the
        rig (replay.py): the unit is the recorded one. ``timebase``: the clock every timed part reads
        and waits on (clock.py; a FakeClock in tests)."""
        self.seed = seed
        self._source = source
        self.serial = source.serial if source else serial or f"SIM{seed:05d}"
        self.model = source.model if source else MODEL
        self.clock: UnitClock = source.clock if source else DeviceClock(seed, timebase=timebase or REAL_CLOCK)
        self.timebase: Clock = self.clock.timebase
        self.config = ConfigStore()
        self.counters: collections.Counter[str] = collections.Counter()
        self.usb_speed = m.UsbSpeed.NOT_USB  # set by the simulated USB bus while plugged (INFO reports it)
        self.lens = LensClass.parse(lens)
        self._truth_cal = lens_calibration(seed, self.lens)
        self.rig = SensorRig(seed, self._truth_cal, self.lens.board_distance_m)
        self._scratch = None
        if flash_path is None:  # a private file removed at close; a killed process's is swept later
            self._scratch = ScratchFlash(self.serial)
            flash_path = self._scratch.path
        self.flash = NorFlash(flash_path, flash_size)
        stored = source.calibration if source else self._truth_cal
        self.calibration = CalibrationService(self.flash, stored or self._truth_cal,
                                              factory_calibrated and stored is not None)
        self.layout = FlashLayout(self.flash)
        provision(self.layout, vendor_key, FACTORY_BUILD, MODEL)
        self._power_lock = threading.RLock()
        self._power_listeners: list[Callable[[str], None]] = []
        self.powered = True
        self._closed = False
        self._epoch = 0
        self.truth = TruthLog(self.rig)
        # the engine's callback reaches the pipeline, which itself needs the engine
        self.dispatcher = Dispatcher(self.counters)
        produce = lambda req: self.pipeline.produce(req)  # noqa: E731 - the pipeline is made below
        self.engine = ReplayEngine(source, produce) if source else CaptureEngine(produce, self.timebase)
        self.repair = FrameRepair(lambda wire: self.link.send(wire, lambda: True))
        self.link: DeviceLink = DeviceLink(self.dispatcher, on_lost=self.engine.stop, on_attach=self.repair.reset,
                                           timebase=self.timebase)
        self.pipeline: CapturePipeline = CapturePipeline(
            seed, self.rig, self.config, self.calibration, self.clock, self.truth, self._send_capture_part,
            self.counters, self.repair, self.engine.count_drop, source)
        self.scene = scene
        self.heartbeat = HeartbeatHandlers(self.clock, self.config, self.engine, self.link, self.counters)
        self.streaming = StreamingHandlers(self.config, self.engine, self.counters)
        self._boot(recovery=False)
        self.trigger_input = TriggerInput(seed, self.streaming.on_pulse)  # its own latency after an edge
        self.trigger_line = trigger_line if trigger_line is not None else TriggerLine(self.timebase)  # unwired
        self.trigger_line.attach(self.trigger_input.on_pulse)  # input still hears its own output
        self.trigger_output = TriggerOutput(self.trigger_line, self.clock, lambda: self.config.snapshot()["fps"])
        self.engine.on_streaming = self._drive_trigger_output
        self.pipeline.warm_up()
        self.watchdog = WatchdogThread(self.heartbeat.watchdog, name=f"watchdog-{self.serial}", timebase=self.timebase)
        registry.register(self)

    # -- boot, reboot, power --------------------------------------------------------------------
    def _boot(self, recovery: bool) -> None:
        """Run the boot stage and become what it booted: its build's version, protocol minor,
        capabilities, parameter defaults and request handlers (recovery: INFO, HEARTBEAT, TIME_SYNC, STOP,
        UPDATE_*)."""
        key = trusted_key(self.flash)
        if key is None:
            raise RuntimeError(f"unit {self.serial} has no trusted key provisioned")
        slots, states = Slots(self.layout, key, MODEL), BootStateStore(self.layout)
        booted = BootStage(slots, states).boot(recovery)
        build = booted.image.build if booted.image else RECOVERY_BUILD
        self.firmware_version = self._source.firmware_version if self._source else build.version
        self.config.reset(build.parameter_defaults, *config_limits(build))
        if self._source:  # a replayed unit starts in the configuration it was recorded with
            self._apply_recorded_config(self._source.boot_config())
        self.update = UpdateService(slots, states, booted)
        identity = Identity(self.model, self.serial, self.firmware_version, build.protocol_minor, build.capabilities)
        groups: list[dict] = [InfoHandler(identity, self.calibration, lambda: self.usb_speed).handlers(),
                              self.heartbeat.handlers()]
        if booted.image is None:
            groups.append({m.MsgType.STOP: self.streaming.handlers()[m.MsgType.STOP]})
        else:
            groups += [ConfigHandlers(self.config, self.engine).handlers(), self.streaming.handlers()]
            if build.capabilities & m.Capability.CALIBRATION:
                groups.append(self.calibration.handlers())
            if build.capabilities & m.Capability.FRAME_REPAIR:
                groups.append(self.repair.handlers())
        if build.capabilities & m.Capability.FIRMWARE_UPDATE:
            groups.append(UpdateHandlers(self.update, self._reset_from(self._epoch), self.power_cut).handlers())
        self.dispatcher.handlers.clear()
        for handlers in groups:
            self.dispatcher.register(handlers)

    @property
    def booted(self) -> Booted:
        """What the boot stage started (its mode turns NORMAL once the host confirms a trial)."""
        return self.update.booted

    def on_power(self, listener: Callable[[str], None]) -> Callable[[], None]:
        """Call ``listener("down")`` when the unit goes down (reset, power cut) and ``("up")`` when it
        has booted again (a USB device re-enumerates); returns the function that unsubscribes."""
        self._power_listeners.append(listener)
        return lambda: self._power_listeners.remove(listener) if listener in self._power_listeners else None

    def _notify(self, event: str) -> None:
        for listener in list(self._power_listeners):
            listener(event)

    def _reset_from(self, epoch: int) -> Callable[[], None]:
        """The reset the running firmware requests (ACTIVATE): void if the unit went down meanwhile."""
        def reset() -> None:
            with self._power_lock:
                if self._epoch == epoch:
                    self.reboot()
        return reset

    def _down(self) -> None:
        self._epoch += 1  # whatever the firmware that ran scheduled dies with it
        self.powered = False
        self._notify("down")
        self.link.detach()

    def _up(self, recovery: bool) -> None:
        self.calibration.reload()
        self._boot(recovery)
        self.powered = True
        self._notify("up")

    def reboot(self, recovery: bool = False) -> None:
        """Reset: the link drops, the boot stage runs again from flash (``recovery``: the recovery
        strap is held), the unit comes back as what it booted."""
        with self._power_lock:
            if self._closed:  # a reboot scheduled by ACTIVATE may fire after close()
                return
            self._down()
            try:
                self._up(recovery)
            except PowerLossError:  # the supply failed during the boot: the unit stays off until power_on()
                pass

    def power_cut(self) -> None:
        """Simulator control: the supply fails now; a flash step in progress or started later fails."""
        self.flash.power_loss_after(0)
        with self._power_lock:
            self._down()

    def power_on(self, recovery: bool = False) -> None:
        """Simulator control: power returns after ``power_cut`` (or a PowerLossError): boot from flash."""
        with self._power_lock:
            self.flash.power_loss_after(None)
            self._up(recovery)

    # -- the host link ------------------------------------------------------------------------
    def attach(self, sink: Sink, hang_up: HangUp | None = None) -> None:
        """Send all further output to ``sink`` (a new host link); ``hang_up`` ends that link when the
        watchdog drops it (SPEC §9)."""
        self.link.attach(sink, hang_up)

    @property
    def attached(self) -> bool:
        """Whether a host link (in-process pipe, pty, socket, USB) currently holds this unit."""
        return self.link.attached

    def detach(self) -> None:
        """The host link is gone: output is discarded and streaming stops."""
        self.link.detach()

    def receive(self, data: bytes) -> None:
        """Bytes from the host; replies go to the sink before this returns (nothing while unpowered)."""
        if self.powered:
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

    def _apply_recorded_config(self, recorded: dict[str, int]) -> None:
        """All of it at once; if the rules refuse the whole (a file from another firmware), each
        parameter alone, keeping the boot default of any still refused."""
        try:
            self.config.apply({BY_NAME[k].pid: v for k, v in recorded.items()}, False)
        except Refusal:
            for name, value in recorded.items():
                try:
                    self.config.apply({BY_NAME[name].pid: value}, False)
                except Refusal as exc:
                    _log.warning("replay of %s: recorded %s=%d not applied: %s", self.serial, name, value, exc)

    def _drive_trigger_output(self, streaming: bool) -> None:
        """SPEC §5.1 ``trigger_output``: the unit pulses the line exactly while its stream runs."""
        if streaming and self.config.snapshot().get("trigger_output") == 1:
            self.trigger_output.drive()
        else:
            self.trigger_output.release()

    def status_counters(self) -> dict[str, int]:
        """The counters a STATUS reply carries."""
        return self.heartbeat.status_counters()

    # -- lifetime -------------------------------------------------------------------------------
    def close(self) -> None:
        with self._power_lock:
            self._closed = True
        registry.unregister(self)
        self.watchdog.close()
        self.engine.close()
        self.pipeline.close()
        self.trigger_line.detach(self.trigger_input.on_pulse)
        self.link.close()
        if self._scratch is not None:
            self._scratch.cleanup()
        if self.pipeline.source is not None:
            self.pipeline.source.close()

    def __enter__(self) -> "SimulatedCamera":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
