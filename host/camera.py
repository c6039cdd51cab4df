"""The Camera API: what a user of the SDK holds."""
from __future__ import annotations

import logging
import os
import queue
import threading
import time
from typing import Iterator

from stereocam.protocol import messages as m
from stereocam.protocol.errors import (CameraTimeoutError, ConfigError, DisconnectedError, StereoCamError,
                                      StreamStalledError, StreamStoppedError, TransportError,
                                      VersionMismatchError)
from stereocam.protocol.framing import VERSION_MAJOR
from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.config_rules import merge
from stereocam.protocol.params import BY_ID, BY_NAME, PARAMS, Param, TriggerMode

from . import calibration_io, firmware_update, presets
from .arguments import config_update, count_arg, flag_arg, timeout_arg
from .device_types import DeviceInfo, DeviceStatus, config_names
from .calibration_io import StoredCalibration
from .callbacks import FrameCallback, FrameCallbacks
from .clock import ArrivalStamp, ClockMap, SyncSample
from .frame_repair import RepairWorker
from .frame_geometry import FrameGeometry
from .frames import AssemblyStats, Frame, FrameAssembler
from .link import Link, LinkStats
from .transports import Transport, open_transport, reopen_url

SYNC_SAMPLES = 8
SYNC_PERIOD = 1.0  # seconds between background time-sync bursts (the map needs them to follow drift)
SYNC_BURST = 3  # round trips per burst: one of them usually finds the link free of frame data
MIN_HEARTBEAT_INTERVAL = 0.01  # s: a faster heartbeat would only load the link
OPEN_OPTIONS = frozenset({"retries", "heartbeat_interval", "queue_depth", "deliver_incomplete", "auto_reconnect"})
_log = logging.getLogger(__name__)


class Camera:
    """One connected camera. Use ``stereocam.open(url)``; close it (or use ``with``) when done."""

    def __init__(self, transport: Transport, *, timeout: float = 1.0, retries: int = 2,
                 heartbeat_interval: float = 0.5, queue_depth: int = 8, deliver_incomplete: bool = False,
                 auto_reconnect: bool = False):
        """``auto_reconnect``: when the link drops, ``get_frame`` (and iteration) call ``reconnect``
        within their own timeout instead of raising DisconnectedError at once."""
        self.url = transport.url
        try:
            self.auto_reconnect = flag_arg(auto_reconnect, "auto_reconnect")
            self.timeout = timeout_arg(timeout)
            heartbeat_interval = timeout_arg(heartbeat_interval, "heartbeat_interval", MIN_HEARTBEAT_INTERVAL)
            self._retries = count_arg(retries, "retries")
            self.clock = ClockMap()
            self.assembler = FrameAssembler(self.clock, count_arg(queue_depth, "queue_depth", 1),
                                            flag_arg(deliver_incomplete, "deliver_incomplete"))
        except ConfigError:
            transport.close()
            raise
        self._closed = threading.Event()
        self._last_sync = 0.0
        self._applied: dict[str, int] = {}  # every parameter this Camera set, for reconnect
        self._geometry = FrameGeometry(self.read_calibration)
        self._streaming = False  # what the user asked for
        self._stream_lock = threading.Lock()  # orders user start/stop against a watchdog restart
        self._stream_epoch = 0  # bumped by every user start/stop: an older STATUS is not acted on
        self._stream_error: StreamStoppedError | None = None
        self.stream_restarts = 0  # streams the device stopped (watchdog) that the host restarted
        self.last_status: DeviceStatus | None = None
        self._callbacks: FrameCallbacks | None = None
        self._repairer = RepairWorker(lambda msg: self.link.request(msg, min(self.timeout, 0.5), 2),
                                      self.assembler.on_resent,
                                      lambda exc: self.link.fail(exc))
        try:
            self._connect(transport)
        except BaseException:
            self._repairer.close()
            raise
        self._heartbeat_interval = heartbeat_interval
        self._heartbeat = threading.Thread(target=self._heartbeat_loop, name="stereocam-heartbeat", daemon=True)
        self._heartbeat.start()

    def _connect(self, transport: Transport) -> None:
        """Bring up a link on ``transport``: identify, stop any stale stream, map the clock."""
        self._arrivals = ArrivalStamp(transport)
        self.link = Link(self._arrivals, timeout=self.timeout, retries=self._retries, on_event=self.assembler.on_message)
        try:
            self._info = self._fetch_info()
            self.assembler.set_limits(self._info.max_width, self._info.max_height)
            self._set_up_repair(transport)
            self.request(m.Stop())  # a known state: no stale stream from a previous session
            self.clock.reset()  # the unit may have rebooted: its clock starts over
            self.sync_clock(SYNC_SAMPLES)
        except BaseException:
            self.link.close()
            raise

    def _set_up_repair(self, transport: Transport) -> None:
        """Protocol 1.2 (SPEC §13): ask for this transport's chunk size and let the assembler request
        resends of damaged parts; with an older device frames travel and drop as in 1.1."""
        self.assembler.repair = None
        if self._info.capabilities & m.Capability.FRAME_REPAIR:
            self.request(m.SetFrameLink(transport.frame_chunk or 0))
            self.assembler.repair = self._repairer.submit

    def reconnect(self, timeout: float = 10.0, backoff: float = 0.1) -> None:
        """After a disconnect: find the same unit again (by serial), re-apply every parameter this
        Camera set, and resume streaming if it was streaming. Retries with exponential backoff
        until ``timeout``; DisconnectedError if the unit does not come back in time."""
        timeout, backoff = timeout_arg(timeout), timeout_arg(backoff, "backoff")
        if self._closed.is_set():
            raise TransportError(f"{self.url}: camera closed; open it again with stereocam.open")
        serial = self._info.serial
        url = reopen_url(self.url, serial)
        deadline = time.monotonic() + timeout
        _log.warning("%s: link lost (%s); reconnecting to serial %s via %s", self.url, self.link.error, serial, url)
        self.link.close()
        while True:
            try:
                self._connect(open_transport(url, self.timeout))
                if self._info.serial != serial:
                    self.link.close()
                    raise TransportError(f"{url} is serial {self._info.serial}, not {serial}")
                break
            except StereoCamError as exc:
                if time.monotonic() + backoff > deadline:
                    raise DisconnectedError(f"camera {serial} did not come back within {timeout:.3g} s: {exc}") \
                        from exc
                time.sleep(backoff)
                backoff = min(backoff * 2, 1.0)
        _log.warning("%s: reconnected to serial %s; re-applying %d parameters%s", self.url, serial,
                     len(self._applied), ", resuming the stream" if self._streaming else "")
        if self._applied:
            self.request(m.SetConfig({BY_NAME[k].pid: v for k, v in self._applied.items()}))
        if self._streaming:
            self.start()

    # -- plumbing ---------------------------------------------------------------------------
    def request(self, msg: m.Message, timeout: float | None = None) -> m.Message:
        return self.link.request(msg, timeout)

    def _fetch_info(self) -> DeviceInfo:
        r = self.request(m.GetInfo())
        assert isinstance(r, m.Info)
        if r.protocol_version[0] != VERSION_MAJOR:
            raise VersionMismatchError(f"device speaks protocol {r.protocol_version[0]}.{r.protocol_version[1]}, "
                                       f"this host speaks {VERSION_MAJOR}.x")
        return DeviceInfo(r.model, r.serial, r.firmware_version, r.protocol_version, r.capabilities,
                          r.sensor_width, r.sensor_height, r.max_payload, r.calibration_id, r.max_width,
                          r.max_height)

    def sync_clock(self, samples: int = 1) -> None:
        """Take ``samples`` time-sync round trips into the device→host clock map."""
        for _ in range(count_arg(samples, "samples", 1)):
            t0 = time.monotonic()
            r = self.request(m.TimeSync())
            t1 = time.monotonic()
            t1 = self._arrivals.last if t0 < self._arrivals.last < t1 else t1  # when the reply came in
            assert isinstance(r, m.Time)
            self.clock.add(SyncSample(t0, r.device_time_us, t1))
        self._last_sync = time.monotonic()

    def _heartbeat_loop(self) -> None:
        while not self._closed.wait(self._heartbeat_interval):
            try:
                epoch = self._stream_epoch
                self.last_status = self.status()
                if not self.last_status.streaming:
                    self._restart_stopped_stream(epoch)
                if time.monotonic() - self._last_sync > SYNC_PERIOD:
                    self.sync_clock(SYNC_BURST)
            except StereoCamError:
                pass  # a dead link shows in the user's next call; reconnect() brings a new one
            except Exception as exc:  # noqa: BLE001 - a bug here ends the link visibly, not silently
                self.link.fail(exc)

    def _restart_stopped_stream(self, epoch: int) -> None:
        """The rule for a stream the device stopped on its own (SPEC §9): the host sends START once
        for each STATUS that shows it stopped while the user wants it streaming, and counts it in
        ``stream_restarts``. If that START is refused or unanswered on a live link, ``get_frame``
        raises StreamStoppedError until the user calls ``start`` (or ``stop``) again."""
        with self._stream_lock:
            if (not self._streaming or self._stream_error is not None or epoch != self._stream_epoch
                    or self._closed.is_set()):
                return
            try:
                self.request(m.Start())
            except StereoCamError as exc:
                if self.link.alive:  # a dead link is reconnect()'s business, which restarts the stream
                    err = StreamStoppedError(f"{self.url} stopped streaming on its own and did not restart: {exc}")
                    err.__cause__ = exc
                    self._stream_error = err
                return
            self.stream_restarts += 1

    # -- API --------------------------------------------------------------------------------
    def info(self) -> DeviceInfo:
        """Identity and state, read now (the calibration id changes when a calibration is written)."""
        self._info = self._fetch_info()
        return self._info

    def read_calibration(self, source: str = "active") -> StoredCalibration | None:
        """The calibration stored on the device (``active``, ``factory`` or ``user``), or None."""
        return calibration_io.read_calibration(self.request, source)

    def write_calibration(self, calibration: StereoCalibration, target: str = "user") -> StoredCalibration:
        """Write, commit, read back and compare; raises VerificationError if the device holds
        anything else, DeviceError if it refused (its previous calibration stays in force)."""
        return calibration_io.write_calibration(self.request, calibration, target)

    def restore_factory_calibration(self) -> StoredCalibration | None:
        return calibration_io.restore_factory(self.request)

    def firmware_status(self) -> firmware_update.FirmwareStatus:
        """Both image slots (version, state, hash read back by the unit) and what runs."""
        return firmware_update.status(self.request)

    def update_firmware(self, image: bytes, progress: firmware_update.Progress | None = None,
                        replace: bool = False) -> firmware_update.UpdateResult:
        """Install a signed image; returns once the unit runs it and it is confirmed (host/firmware_update.py)."""
        if not isinstance(image, (bytes, bytearray, memoryview)):
            raise ConfigError(f"a firmware image is bytes (the signed file's contents), got {type(image).__name__}")
        return firmware_update.update(self, bytes(image), progress=progress, replace=replace)

    def config(self) -> dict[str, int]:
        r = self.request(m.GetConfig())
        return config_names(r.values)  # type: ignore[attr-defined]

    def configure(self, **params: int) -> dict[str, int]:
        """Change parameters by name (protocol/params.py); returns the whole new configuration.

        All or nothing: the device checks the whole set and a refusal changes nothing.
        """
        update = config_update(params)
        r = self.request(m.SetConfig(update))
        self._applied.update({BY_ID[k].name: v for k, v in update.items()})
        return config_names(r.values)  # type: ignore[attr-defined]

    def check_config(self, **params: int) -> dict[str, int]:
        """The configuration ``configure(**params)`` would give, checked here against the
        protocol's rules (protocol/config_rules.py) without changing the device; ConfigRejected
        (a ConfigError naming the parameter, ``.param``, and the NACK code) if the device would
        refuse it (also a value needing a capability this device does not advertise). The device
        stays the authority: ``configure`` still sends the request."""
        return merge(self.config(), config_update(params), self._streaming, self._info.capabilities)

    def set_trigger_mode(self, mode: TriggerMode | str) -> None:
        """``mode``: a TriggerMode, its name ("free_run", "software", "external") or its number."""
        if isinstance(mode, str):
            try:
                mode = TriggerMode[mode.upper().replace("-", "_")]
            except KeyError as exc:
                raise ConfigError(f"unknown trigger mode {mode!r}; known: free_run, software, external") from exc
        if isinstance(mode, int) and not isinstance(mode, (bool, TriggerMode)) and mode in set(TriggerMode):
            mode = TriggerMode(mode)
        if not isinstance(mode, TriggerMode):
            raise ConfigError(f"trigger mode must be a TriggerMode, its name or its number, got {mode!r}")
        self.configure(trigger_mode=int(mode))

    def trigger(self) -> int:
        """Software trigger; returns the trigger id the resulting frame will carry."""
        r = self.request(m.Trigger())
        assert isinstance(r, m.Triggered)
        return r.trigger_id

    def start(self) -> None:
        """Start streaming; frames still queued from an earlier stream are discarded."""
        with self._stream_lock:
            self._stream_epoch += 1
            self.assembler.reset()
            self.request(m.Start())
            self._streaming = True
            self._stream_error = None

    def stop(self) -> None:
        with self._stream_lock:
            self._stream_epoch += 1
            self.request(m.Stop())
            self._streaming = False
            self._stream_error = None

    @property
    def streaming(self) -> bool:
        """Whether this Camera started the stream (and has not stopped it)."""
        return self._streaming

    def status(self) -> DeviceStatus:
        r = self.request(m.Heartbeat())
        assert isinstance(r, m.Status)
        return DeviceStatus(r.uptime_us, r.streaming, TriggerMode(r.trigger_mode), r.counters)

    def get_frame(self, timeout: float | None = None) -> Frame:
        """The next complete frame; CameraTimeoutError (a TimeoutError) if none within ``timeout``
        (finite seconds >= 0; ConfigError otherwise). ``timeout=0`` polls: a queued frame at once, or
        the error at once. StreamStoppedError if the device stopped the stream and would not restart
        (see ``_restart_stopped_stream``)."""
        if self._callbacks is not None and len(self._callbacks):
            raise StereoCamError("frames go to the on_frame callbacks; remove them (cam.remove_callback) "
                                 "before calling get_frame")
        timeout = self.timeout if timeout is None else timeout_arg(timeout)
        frame = self._next_frame(timeout)
        if frame is None:
            raise CameraTimeoutError(f"no frame from {self.url} within {timeout:.3g} s")
        return frame

    def try_get_frame(self) -> Frame | None:
        """A queued frame, or None at once if there is none (never waits)."""
        return self._next_frame(0.0)

    def _next_frame(self, timeout: float) -> Frame | None:
        """The next frame within ``timeout`` (a queued one first, even at 0), else None."""
        deadline = time.monotonic() + timeout
        while True:
            if self._stream_error is not None:
                raise self._stream_error
            try:
                self.link.check_alive()
            except DisconnectedError:
                if not self.auto_reconnect or self._closed.is_set():
                    raise
                self.reconnect(timeout=max(deadline - time.monotonic(), 0.0))
            left = deadline - time.monotonic()
            try:
                frame = self.assembler.frames.get(timeout=min(left, 0.1)) if left > 0 else \
                    self.assembler.frames.get_nowait()
            except queue.Empty:
                if left <= 0:
                    return None
                continue
            return self._with_stored_calibration(frame)

    def on_frame(self, fn: FrameCallback) -> FrameCallback:
        """Call ``fn(frame)`` for every frame, on a thread of this Camera's (not the link's reader).
        While any callback is registered frames go to the callbacks, not to ``get_frame``. A callback
        that raises is logged and counted (``callback_errors``); ``check_callbacks()`` re-raises it.
        Returns ``fn``, so it also works as a decorator."""
        if not callable(fn):
            raise ConfigError(f"a frame callback must be callable, got {fn!r}")
        if self._closed.is_set():
            raise TransportError(f"{self.url}: camera closed")
        if self._callbacks is None:
            self._callbacks = FrameCallbacks(self._next_frame)
        self._callbacks.add(fn)
        return fn

    def remove_callback(self, fn: FrameCallback) -> None:
        if self._callbacks is None or not self._callbacks.remove(fn):
            raise ConfigError(f"{fn!r} is not a registered frame callback")

    @property
    def callback_errors(self) -> int:
        """How many callback calls raised."""
        return 0 if self._callbacks is None else self._callbacks.errors

    def check_callbacks(self) -> None:
        """Raise CallbackError (from the callback's exception) if a frame callback has raised."""
        if self._callbacks is not None:
            self._callbacks.check()

    def _with_stored_calibration(self, frame: Frame) -> Frame:
        """A device with calibration storage: the frame's geometry as this host derives it from the
        stored calibration (frame_geometry.py); otherwise the device's own."""
        if not self._info.capabilities & m.Capability.CALIBRATION:
            return frame
        return self._geometry.apply(frame)

    @property
    def geometry_mismatches(self) -> int:
        """Frames whose carried geometry disagreed with the one derived from the stored calibration."""
        return self._geometry.mismatches

    def record(self, path: str, *, frames: int | None = None, seconds: float | None = None, **options):
        """Record to an MCAP file (ROS 2 profile) until ``frames`` or ``seconds``; see stereocam.recording."""
        from .recording import record

        return record(self, path, frames=frames, seconds=seconds, **options)

    def __iter__(self) -> Iterator[Frame]:
        """Frames as they come while streaming. Ends when the stream is stopped (``stop()`` from any
        thread, ``close()``) and the queued frames are taken; raises StreamStalledError (a
        CameraTimeoutError) when streaming but no frame came for ``timeout`` seconds."""
        if not self._streaming:
            raise StereoCamError("not streaming: call start() before iterating over the camera")
        while True:
            deadline = time.monotonic() + self.timeout
            while (frame := self._next_frame(min(0.1, max(deadline - time.monotonic(), 0.0)))) is None:
                if not self._streaming or self._closed.is_set():
                    return
                if time.monotonic() >= deadline:
                    raise StreamStalledError(f"{self.url} is streaming but sent no frame for {self.timeout:.3g} s "
                                             "(software trigger mode waits for trigger())")
            yield frame

    # -- configuration ------------------------------------------------------------------------
    @staticmethod
    def options() -> list[Param]:
        """Every parameter: name, range (lo..hi, step, odd), unit, default, description, live."""
        return list(PARAMS)

    def save_preset(self, path: str | os.PathLike) -> dict[str, int]:
        """Write the whole current configuration to ``path`` as JSON; returns it."""
        config = self.config()
        presets.write_preset(path, config, self._info.model)
        return config

    def load_preset(self, path: str | os.PathLike) -> dict[str, int]:
        """Apply a preset written by ``save_preset`` (all or nothing: a refusal changes nothing);
        returns the new configuration. ConfigError for a file that is not a preset."""
        return self.configure(**presets.read_preset(path))

    @property
    def stats(self) -> dict[str, int]:
        """Host-side counters: decoder, link and frame assembly."""
        out = self.link.decoder.stats.as_dict()
        out.update(_fields(self.link.stats))
        out.update(_fields(self.assembler.stats))
        out["frames_dropped"] = self.assembler.stats.dropped
        return out

    def close(self) -> None:
        if self._closed.is_set():
            return
        self._closed.set()
        if self._callbacks is not None:
            self._callbacks.close()
        if self.link.alive:
            try:
                self.request(m.Stop(), timeout=0.5)
            except StereoCamError:
                pass
        self._heartbeat.join(timeout=2)
        self.link.close()  # first: a resend request in flight then fails at once
        self._repairer.close()

    def __enter__(self) -> "Camera":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _fields(obj: LinkStats | AssemblyStats) -> dict[str, int]:
    return {k: getattr(obj, k) for k in obj.__dataclass_fields__}


def open(url: str, timeout: float = 1.0, **kwargs) -> Camera:  # noqa: A001 - mirrors serial_for_url
    """Open the camera at ``url`` (sim://, usb://, socket://host:port, a device path, ...); the
    keyword arguments are ``Camera``'s (retries, heartbeat_interval, queue_depth, ...)."""
    timeout = timeout_arg(timeout)
    unknown = sorted(set(kwargs) - OPEN_OPTIONS)
    if unknown:
        raise ConfigError(f"unknown option{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}; "
                          f"known: timeout, {', '.join(sorted(OPEN_OPTIONS))}")
    return Camera(open_transport(url, timeout), timeout=timeout, **kwargs)
