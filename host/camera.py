"""The Camera API: what a user of the SDK holds."""
from __future__ import annotations

import logging
import os
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterator

from stereocam.protocol import messages as m
from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.config_rules import merge
from stereocam.protocol.errors import (CameraTimeoutError, ConfigError, DisconnectedError, EndOfRecordingError,
                                      StereoCamError, StreamStalledError, StreamStoppedError, TransportError)
from stereocam.protocol.params import BY_ID, BY_NAME, PARAMS, Param, TriggerMode

from . import calibration_io, firmware_update, presets
from .arguments import config_update, count_arg, flag_arg, timeout_arg
from .calibration_io import StoredCalibration
from .callbacks import FrameCallback, FrameCallbacks
from .connection import HEARTBEAT_INTERVAL, MIN_HEARTBEAT_INTERVAL, Connection, Counters
from .device_types import DeviceInfo, DeviceStatus, config_names
from .dispatch import DropPolicy, FrameDispatcher, FrameQueue, Listener
from .frame_geometry import FrameGeometry
from .frames import Frame
from .transports import Transport, open_transport

if TYPE_CHECKING:
    from .recording.recorder import RecorderStats
    from .recording.session import Progress

__all__ = ["Camera", "Counters", "DeviceInfo", "DeviceStatus", "open"]

OPEN_OPTIONS = frozenset({"retries", "heartbeat_interval", "queue_depth", "deliver_incomplete", "auto_reconnect"})
_log = logging.getLogger(__name__)


class Camera:
    """One connected camera. Use ``stereocam.open(url)``; close it (or use ``with``) when done.

    The user API over a Connection (link, heartbeat, clock map, reconnect, frame repair) and a
    FrameDispatcher that hands every frame to each listener: the ``get_frame`` queue (or the
    ``on_frame`` callbacks), and any added with ``add_listener`` (a recorder, a viewer)."""

    def __init__(self, transport: Transport, *, timeout: float = 1.0, retries: int = 2,
                 heartbeat_interval: float = HEARTBEAT_INTERVAL, queue_depth: int = 8, deliver_incomplete: bool = False,
                 auto_reconnect: bool = False):
        """``auto_reconnect``: when the link drops, ``get_frame`` (and iteration) call ``reconnect``
        within their own timeout instead of raising DisconnectedError at once."""
        self.url = transport.url
        try:
            self.auto_reconnect = flag_arg(auto_reconnect, "auto_reconnect")
            self.timeout = timeout_arg(timeout)
            retries = count_arg(retries, "retries")
            self._queue_depth = count_arg(queue_depth, "queue_depth", 1)
            deliver_incomplete = flag_arg(deliver_incomplete, "deliver_incomplete")
            heartbeat_interval = timeout_arg(heartbeat_interval, "heartbeat_interval", MIN_HEARTBEAT_INTERVAL)
        except ConfigError:
            transport.close()
            raise
        self._applied: dict[str, int] = {}  # every parameter this Camera set, for reconnect
        self._geometry = FrameGeometry()
        self._dispatcher = FrameDispatcher()
        self._frames = FrameQueue("get_frame", self._queue_depth, DropPolicy.DROP_OLDEST)
        self._dispatcher.add(self._frames)
        self._callbacks: FrameCallbacks | None = None
        self._streaming = False  # what the user asked for
        self._stream_lock = threading.Lock()  # orders user start/stop against a watchdog restart
        self._stream_changed = 0.0  # when the user last started or stopped: an older STATUS is not acted on
        self._stream_error: StreamStoppedError | None = None
        self._restarts = 0
        self.connection = Connection(transport, self._dispatch, self._on_status, timeout=self.timeout,
                                     retries=retries, heartbeat_interval=heartbeat_interval,
                                     deliver_incomplete=deliver_incomplete)
        self.clock = self.connection.clock
        try:
            self._resolve_geometry()
        except BaseException:
            self.connection.close()
            raise
        self.connection.start_heartbeat()

    def _dispatch(self, frame: Frame) -> None:
        """Every assembled frame, with its geometry, to every listener (on the reader thread: no I/O)."""
        self._dispatcher.dispatch(self._geometry.apply(frame))

    def _resolve_geometry(self) -> None:
        """Read the calibration in force (a device that stores one), for the geometry of the frames
        from now on; without calibration storage frames keep the device's own geometry."""
        calibrated = self.connection.info.capabilities & m.Capability.CALIBRATION
        self._geometry.resolve(self.read_calibration() if calibrated else None)

    def reconnect(self, timeout: float = 10.0, backoff: float = 0.1, expected: bool = False) -> None:
        """After a disconnect: find the same unit again (by serial), re-apply every parameter this
        Camera set, and resume streaming if it was streaming. Retries with exponential backoff
        until ``timeout``; DisconnectedError if the unit does not come back in time. ``expected``: the
        caller made the unit reset (a firmware update): logged at INFO, not as a WARNING."""
        self.connection.reconnect(timeout, backoff, expected)
        _log.log(logging.INFO if expected else logging.WARNING, "%s: reconnected to serial %s; re-applying %d parameters%s", self.url, self.connection.info.serial,
                     len(self._applied), ", resuming the stream" if self._streaming else "")
        self._resolve_geometry()
        # the unit may not have noticed the lost link yet and still stream for it (SPEC §4.6: STOP is
        # always answered, streaming or not); a stream must be stopped before its format changes
        self.request(m.Stop())
        if self._applied:
            self.request(m.SetConfig({BY_NAME[k].pid: v for k, v in self._applied.items()}))
        if self._streaming:
            self.start()

    # -- plumbing ---------------------------------------------------------------------------
    def request(self, msg: m.Message, timeout: float | None = None) -> m.Message:
        """Send one protocol message and return the device's reply (protocol/messages.py)."""
        return self.connection.request(msg, timeout)

    @property
    def alive(self) -> bool:
        """Whether the link to the unit is up."""
        return self.connection.alive

    @property
    def last_status(self) -> DeviceStatus | None:
        """The STATUS of the latest heartbeat (None before the first)."""
        return self.connection.last_status

    @property
    def stream_restarts(self) -> int:
        """Streams the device stopped (watchdog) that the host restarted."""
        return self._restarts

    def sync_clock(self, samples: int = 1) -> None:
        """Take ``samples`` time-sync round trips into the device→host clock map."""
        self.connection.sync_clock(samples)

    def _on_status(self, status: DeviceStatus, asked_at: float) -> None:
        """The rule for a stream the device stopped on its own (SPEC §9): the host sends START once
        for each STATUS that shows it stopped while the user wants it streaming, and counts it in
        ``stream_restarts``. If that START is refused or unanswered on a live link, ``get_frame``
        raises StreamStoppedError until the user calls ``start`` (or ``stop``) again."""
        if status.streaming:
            return
        with self._stream_lock:
            if (not self._streaming or self._stream_error is not None or asked_at < self._stream_changed
                    or self.connection.closed):
                return
            try:
                self.request(m.Start())
            except StereoCamError as exc:
                if self.alive:  # a dead link is reconnect()'s business, which restarts the stream
                    err = StreamStoppedError(f"{self.url} stopped streaming on its own and did not restart: {exc}")
                    err.__cause__ = exc
                    self._stream_error = err
                return
            self._restarts += 1

    # -- API --------------------------------------------------------------------------------
    def info(self) -> DeviceInfo:
        """Identity and state, read now (the calibration id changes when a calibration is written)."""
        return self.connection.refresh_info()

    def read_calibration(self, source: str = "active") -> StoredCalibration | None:
        """The calibration stored on the device (``active``, ``factory`` or ``user``), or None."""
        return calibration_io.read_calibration(self.request, source)

    def write_calibration(self, calibration: StereoCalibration, target: str = "user") -> StoredCalibration:
        """Write, commit, read back and compare; raises VerificationError if the device holds
        anything else, DeviceError if it refused (its previous calibration stays in force)."""
        stored = calibration_io.write_calibration(self.request, calibration, target)
        self._resolve_geometry()
        return stored

    def restore_factory_calibration(self) -> StoredCalibration | None:
        stored = calibration_io.restore_factory(self.request)
        self._resolve_geometry()
        return stored

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
        assert isinstance(r, m.Config)
        return config_names(r.values)

    def configure(self, **params: int) -> dict[str, int]:
        """Change parameters by name (protocol/params.py); returns the whole new configuration.

        All or nothing: the device checks the whole set and a refusal changes nothing.
        """
        update = config_update(params)
        r = self.request(m.SetConfig(update))
        assert isinstance(r, m.ConfigApplied)
        self._applied.update({BY_ID[k].name: v for k, v in update.items()})
        return config_names(r.values)

    def check_config(self, **params: int) -> dict[str, int]:
        """The configuration ``configure(**params)`` would give, checked here against the
        protocol's rules (protocol/config_rules.py) without changing the device; ConfigRejected
        (a ConfigError naming the parameter, ``.param``, and the NACK code) if the device would
        refuse it (also a value needing a capability this device does not advertise, or a format
        beyond the selected matcher's INFO stage limit). The device stays the authority:
        ``configure`` still sends the request."""
        info = self.connection.info
        limits = {m.Stage.BLOCK_MATCHING: info.stage_limit(m.Stage.BLOCK_MATCHING),
                  m.Stage.SEMI_GLOBAL: info.stage_limit(m.Stage.SEMI_GLOBAL)}
        return merge(self.config(), config_update(params), self._streaming, info.effective_capabilities, limits)

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
            self._stream_changed = time.monotonic()
            self.connection.assembler.reset()
            self._frames.clear()
            self.request(m.Start())
            self._streaming = True
            self._stream_error = None

    def stop(self) -> None:
        with self._stream_lock:
            self._stream_changed = time.monotonic()
            self.request(m.Stop())
            self._streaming = False
            self._stream_error = None

    @property
    def streaming(self) -> bool:
        """Whether this Camera started the stream (and has not stopped it)."""
        return self._streaming

    def status(self) -> DeviceStatus:
        """The device's state, asked for now (HEARTBEAT)."""
        return self.connection.status()

    def get_frame(self, timeout: float | None = None) -> Frame:
        """The next complete frame; CameraTimeoutError (a TimeoutError) if none within ``timeout``
        (finite seconds >= 0; ConfigError otherwise). ``timeout=0`` polls: a queued frame at once, or
        the error at once. EndOfRecordingError (naming the file) once a replayed recording's last frame
        has been taken. StreamStoppedError if the device stopped the stream and would not restart
        (see ``_restart_stopped_stream``). Not streaming with no frame queued: the CameraTimeoutError
        at once, saying so (no frame would come: call ``start`` first)."""
        if self._callbacks is not None and len(self._callbacks):
            raise StereoCamError("frames go to the on_frame callbacks; remove them (cam.remove_callback) "
                                 "before calling get_frame")
        timeout = self.timeout if timeout is None else timeout_arg(timeout)
        if not self._streaming and len(self._frames) == 0 and not self.connection.closed:
            raise CameraTimeoutError(f"no frame from {self.url}: it is not streaming (call start() before get_frame(); "
                                     "no frame would come)")
        frame = self._next_frame(timeout)
        if frame is None:
            raise CameraTimeoutError(f"no frame from {self.url} within {timeout:.3g} s")
        return frame

    def try_get_frame(self) -> Frame | None:
        """A queued frame, or None at once if there is none (never waits)."""
        return self._next_frame(0.0)

    def _next_frame(self, timeout: float) -> Frame | None:
        """The next frame of the get_frame queue within ``timeout`` (a queued one first, even at 0),
        else None. No request goes to the device (a reconnect with ``auto_reconnect`` aside)."""
        deadline = time.monotonic() + timeout
        while True:
            if self._stream_error is not None:
                raise self._stream_error
            try:
                self.connection.check_alive()
            except DisconnectedError:
                if not self.auto_reconnect or self.connection.closed:
                    raise
                self.reconnect(timeout=max(deadline - time.monotonic(), 0.0))
            left = deadline - time.monotonic()
            frame = self._frames.get(min(left, 0.1) if left > 0 else 0.0)
            if frame is None and self._streaming and (path := self.connection.ended()) is not None:
                frame = self._last_of_recording(path)
            if frame is not None or left <= 0:
                return frame

    def _last_of_recording(self, path: str) -> Frame:
        """A frame still on its way from a replay that reached its end, else EndOfRecordingError: a
        round trip first (every frame sent before the reply has then been delivered)."""
        self.connection.status()
        frame = self._frames.get(0.0)
        if frame is None:
            raise EndOfRecordingError(f"{self.url}: end of recording {path} (every frame was delivered; "
                                      "?loop=1 plays it again)", path)
        return frame

    @property
    def frames(self) -> FrameQueue:
        """The get_frame queue: ``len`` is how many frames wait, ``dropped`` how many it discarded."""
        return self._frames

    def add_listener(self, listener: Listener) -> None:
        """Hand every frame from now on to ``listener.put`` too, which must not block: a FrameQueue
        (dispatch.py, its own size and drop policy), a RecordingListener, ... (python-can's Notifier)."""
        if not callable(getattr(listener, "put", None)):
            raise ConfigError(f"a frame listener has a put(frame) method, got {listener!r}")
        self._dispatcher.add(listener)

    def remove_listener(self, listener: Listener) -> None:
        self._dispatcher.remove(listener)

    def on_frame(self, fn: FrameCallback) -> FrameCallback:
        """Call ``fn(frame)`` for every frame, on a thread of this Camera's (not the link's reader).
        While any callback is registered frames go to the callbacks, not to ``get_frame``. A callback
        that raises is logged and counted (``callback_errors``); ``check_callbacks()`` re-raises it.
        Returns ``fn``, so it also works as a decorator."""
        if not callable(fn):
            raise ConfigError(f"a frame callback must be callable, got {fn!r}")
        if self.connection.closed:
            raise TransportError(f"{self.url}: camera closed")
        if self._callbacks is None:
            self._callbacks = FrameCallbacks(self._queue_depth)
        self._callbacks.add(fn)
        self._dispatcher.remove(self._frames)
        self._dispatcher.add(self._callbacks)
        return fn

    def remove_callback(self, fn: FrameCallback) -> None:
        if self._callbacks is None or not self._callbacks.remove(fn):
            raise ConfigError(f"{fn!r} is not a registered frame callback")
        if not len(self._callbacks):  # frames go to get_frame again
            self._dispatcher.remove(self._callbacks)
            self._callbacks.queue.clear()
            self._dispatcher.add(self._frames)

    @property
    def callback_errors(self) -> int:
        """How many callback calls raised."""
        return 0 if self._callbacks is None else self._callbacks.errors

    def check_callbacks(self) -> None:
        """Raise CallbackError (from the callback's exception) if a frame callback has raised."""
        if self._callbacks is not None:
            self._callbacks.check()

    @property
    def geometry_mismatches(self) -> int:
        """Frames whose carried geometry disagreed with the one derived from the stored calibration."""
        return self._geometry.mismatches

    def record(self, path: str | Path, *, frames: int | None = None, seconds: float | None = None,
               progress: Callable[[Progress], None] | None = None, **options: object) -> RecorderStats:
        """Record to an MCAP file (ROS 2 profile) until ``frames`` or ``seconds``; see stereocam.recording."""
        from .recording import record

        return record(self, path, frames=frames, seconds=seconds, progress=progress, **options)

    def __iter__(self) -> Iterator[Frame]:
        """Frames as they come while streaming. Ends when the stream is stopped (``stop()`` from any
        thread, ``close()``) and the queued frames are taken, or when a replayed recording's last frame
        was taken; raises StreamStalledError (a CameraTimeoutError) when streaming but no frame came
        for ``timeout`` seconds."""
        if not self._streaming:
            raise StereoCamError("not streaming: call start() before iterating over the camera")
        while True:
            deadline = time.monotonic() + self.timeout
            while True:
                try:
                    frame = self._next_frame(min(0.1, max(deadline - time.monotonic(), 0.0)))
                except EndOfRecordingError:
                    return
                if frame is not None:
                    break
                if not self._streaming or self.connection.closed:
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
        presets.write_preset(path, config, self.connection.info.model)
        return config

    def load_preset(self, preset: str | os.PathLike) -> dict[str, int]:
        """Apply a named preset ('high_density', 'high_accuracy', 'off': the values it names) or one
        written by ``save_preset`` (all or nothing: a refusal changes nothing); returns the new
        configuration. ConfigError for a file that is not a preset."""
        return self.configure(**presets.preset_values(preset))

    def counters(self) -> Counters:
        """Host-side counters (link, decoder, frame assembly, delivery), one consistent snapshot."""
        return replace(self.connection.counters(), queue_overflow=self._frames.dropped,
                       stream_restarts=self._restarts)

    @property
    def stats(self) -> dict[str, int]:
        """``counters()`` by name, flat."""
        return self.counters().as_dict()

    def close(self) -> None:
        if self.connection.closed:
            return
        if self._callbacks is not None:
            self._callbacks.close()
        self.connection.close()

    def __repr__(self) -> str:
        state = "closed" if self.connection.closed else "streaming" if self._streaming else "stopped"
        info = self.connection.info
        return f"<Camera {self.url} {info.model} serial={info.serial} firmware={info.firmware_version} {state}>"

    def __enter__(self) -> "Camera":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open(url: str, timeout: float = 1.0, **kwargs) -> Camera:  # noqa: A001 - mirrors serial_for_url
    """Open the camera at ``url`` (sim://, usb://, socket://host:port, a device path, ...); the
    keyword arguments are ``Camera``'s (retries, heartbeat_interval, queue_depth, ...)."""
    timeout = timeout_arg(timeout)
    unknown = sorted(set(kwargs) - OPEN_OPTIONS)
    if unknown:
        raise ConfigError(f"unknown option{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}; "
                          f"known: timeout, {', '.join(sorted(OPEN_OPTIONS))}")
    return Camera(open_transport(url, timeout), timeout=timeout, **kwargs)
