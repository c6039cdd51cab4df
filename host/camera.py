"""The Camera API: what a user of the SDK holds."""
from __future__ import annotations

import logging
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterator

from stereocam.protocol import messages as m
from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.errors import ConfigError, StereoCamError, StreamStoppedError, TransportError
from stereocam.protocol.params import BY_NAME

from . import calibration_io, firmware_update
from .arguments import count_arg, flag_arg, request_timeout_arg, retries_arg, timeout_arg, url_arg
from .calibration_io import StoredCalibration
from .callbacks import FrameCallbacks
from .camera_frames import FrameDelivery
from .camera_settings import CameraSettings
from .connection import HEARTBEAT_INTERVAL, MIN_HEARTBEAT_INTERVAL, Connection, Counters
from .device_types import DeviceInfo, DeviceStatus
from .dispatch import DropPolicy, FrameDispatcher, FrameQueue
from .frame_geometry import FrameGeometry
from .frames import Frame
from .transports import Transport, open_transport

if TYPE_CHECKING:
    from .recording.recorder import RecorderStats
    from .recording.session import Progress

__all__ = ["Camera", "Counters", "DeviceInfo", "DeviceStatus", "open"]

OPEN_OPTIONS = frozenset({"retries", "heartbeat_interval", "queue_depth", "deliver_incomplete", "auto_reconnect"})
_log = logging.getLogger(__name__)


class Camera(CameraSettings, FrameDelivery):
    """One connected camera. Use ``stereocam.open(url)``; close it (or use ``with``) when done.

    The user API over a Connection (link, heartbeat, clock map, reconnect, frame repair) and a
    FrameDispatcher that hands every frame to each listener: the ``get_frame`` queue (or the
    ``on_frame`` callbacks), and any added with ``add_listener`` (a recorder, a viewer). Here: the
    link, the stream, calibration and firmware; its configuration is CameraSettings's
    (camera_settings.py), the frames it hands out FrameDelivery's (camera_frames.py)."""

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
        _log.log(logging.INFO if expected else logging.WARNING, "%s: reconnected to serial %s; re-applying %d "
                 "parameters%s", self.url, self.connection.info.serial, len(self._applied),
                 ", resuming the stream" if self._streaming else "")
        self._resolve_geometry()
        # the unit may not have noticed the lost link yet and still stream for it (SPEC §4.6: STOP is
        # always answered, streaming or not); a stream must be stopped before its format changes.
        # Under the stream lock, as a user's stop and start: a heartbeat's STATUS of the unit not
        # streaming would otherwise have its START sent between this STOP and the SET_CONFIG, which
        # the unit then refuses (BAD_STATE: a format change while streaming)
        with self._stream_lock:
            self._stream_changed = time.monotonic()
            self.request(m.Stop())
            if self._applied:
                self.request(m.SetConfig({BY_NAME[k].pid: v for k, v in self._applied.items()}))
            if self._streaming:
                self._start_stream()

    def _start_stream(self) -> None:
        """START, with the get_frame queue and frame assembly starting over (the stream lock held)."""
        self._stream_changed = time.monotonic()
        self.connection.assembler.reset()
        self._frames.clear()
        self.request(m.Start())
        self._streaming = True
        self._stream_error = None

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

    def trigger(self) -> int:
        """Software trigger; returns the trigger id the resulting frame will carry."""
        r = self.request(m.Trigger())
        assert isinstance(r, m.Triggered)
        return r.trigger_id

    def start(self) -> None:
        """Start streaming; frames still queued from an earlier stream are discarded."""
        with self._stream_lock:
            self._start_stream()

    def stop(self) -> None:
        with self._stream_lock:
            self._stream_changed = time.monotonic()
            self.request(m.Stop())
            self._streaming = False
            self._stream_error = None

    @property
    def streaming(self) -> bool:
        """Whether this Camera started the stream (and has neither stopped it nor been closed)."""
        return self._streaming and not self.connection.closed

    def __iter__(self) -> Iterator[Frame]:
        """FrameDelivery's iteration, which also ends (StopIteration) once ``close()`` was called,
        from any thread: the closed link's error is the end of the stream then, not a failure. A link
        lost to a fault while the camera is open still raises (DisconnectedError, ...)."""
        try:
            yield from super().__iter__()
        except TransportError:
            if not self.connection.closed:
                raise

    def status(self) -> DeviceStatus:
        """The device's state, asked for now (HEARTBEAT)."""
        return self.connection.status()

    @property
    def geometry_mismatches(self) -> int:
        """Frames whose carried geometry disagreed with the one derived from the stored calibration."""
        return self._geometry.mismatches

    def record(self, path: str | Path, *, frames: int | None = None, seconds: float | None = None,
               progress: Callable[[Progress], None] | None = None, **options: object) -> RecorderStats:
        """Record to an MCAP file (ROS 2 profile) until ``frames`` or ``seconds``; see stereocam.recording."""
        from .recording import record

        return record(self, path, frames=frames, seconds=seconds, progress=progress, **options)

    def counters(self) -> Counters:
        """Host-side counters (link, decoder, frame assembly, delivery), one consistent snapshot."""
        return replace(self.connection.counters(), queue_overflow=self._frames.dropped,
                       stream_restarts=self._restarts)

    @property
    def stats(self) -> dict[str, int]:
        """``counters()`` by name, flat."""
        return self.counters().as_dict()

    def close(self) -> None:
        """Stop the stream and end the link; idempotent. A frame callback still running is waited for
        up to ``callbacks.CLOSE_WAIT`` s (not when close() is called from a callback); if it runs
        longer a WARNING names it, no callback is called after close(), and the callbacks' thread
        ends when that one returns."""
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


def open(url: str, timeout: float = 1.0, **kwargs) -> Camera:  # the builtin open's name, as serial_for_url
    """Open the camera at ``url`` (sim://, usb://, socket://host:port, a device path, ...); the
    keyword arguments are ``Camera``'s (retries, heartbeat_interval, queue_depth, ...)."""
    url = url_arg(url)
    timeout = request_timeout_arg(timeout)
    unknown = sorted(set(kwargs) - OPEN_OPTIONS)
    if unknown:
        raise ConfigError(f"unknown option{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}; "
                          f"known: timeout, {', '.join(sorted(OPEN_OPTIONS))}")
    if "retries" in kwargs:
        retries_arg(kwargs["retries"])  # before the transport opens (Connection checks it again)
    return Camera(open_transport(url, timeout), timeout=timeout, **kwargs)
