"""Record a live camera: read what the file says about the unit, stream, and hand every frame to a
Recorder as a listener of the camera's frame dispatcher (no grab loop: ``get_frame`` gets the same
frames at the same time)."""
from __future__ import annotations

import os
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from stereocam.protocol.errors import ConfigError, StreamStalledError
from stereocam.protocol.params import TriggerMode

from ..arguments import count_arg, timeout_arg
from ..frame_types import Frame
from .convert import LinkCounters
from .recorder import Recorder, RecorderStats, RecordingError, UnitDescription, check_options

RECORDER_OPTIONS = frozenset({"queue_bytes", "level", "threads", "chunk_bytes"})  # what record() passes on

if TYPE_CHECKING:
    from stereocam.camera import Camera

PROGRESS_PERIOD = 0.5  # seconds between progress reports
WAIT_STEP = 0.02  # seconds between looks at the limits while frames go to the recorder


@dataclass(frozen=True)
class Progress:
    frames: int
    seconds: float
    fps: float
    camera_mbps: float  # plane bytes per second, as the camera sends them
    file_mbps: float
    counters: LinkCounters  # drops so far by where they happened
    backlog_mb: float  # queued for the writer

    def line(self) -> str:
        c = self.counters
        return (f"{self.frames} frames  {self.seconds:6.1f} s  {self.fps:5.1f} fps  {self.camera_mbps:6.1f} MB/s in  "
                f"{self.file_mbps:6.1f} MB/s to disk  drops: sequence gaps {c.link_lost} (device skipped "
                f"{c.device_dropped}) incomplete {c.link_incomplete} host {c.host_queue_overflow} recorder "
                f"{c.recorder_dropped}  "
                f"backlog {self.backlog_mb:.0f} MB")


def describe(camera: "Camera") -> UnitDescription:
    """INFO, configuration and the stored calibration of ``camera``, read now."""
    info = {k: ".".join(map(str, v)) if isinstance(v, tuple) else str(v) for k, v in asdict(camera.info()).items()}
    return UnitDescription(info, camera.config(), camera.read_calibration())


def counters_of(camera: "Camera") -> LinkCounters:
    """The camera's and the link's drop counters so far (the recorder adds its own). A recorder
    listens to the dispatcher directly, so no host queue stands between them (host_queue_overflow 0)."""
    st = camera.counters().assembly
    status = camera.last_status
    return LinkCounters(link_lost=st.lost, link_incomplete=st.incomplete + st.size_mismatch + st.device_errors,
                        device_dropped=status.counters.get("frames_dropped", 0) if status else 0)


class RecordingListener:
    """A frame listener that hands each frame to a Recorder (whose bounded queue drops the newest
    frame when the disk falls behind, counted as recorder_dropped), up to ``frames`` of them.
    ``done`` is set at the limit or when writing failed (``error``)."""

    def __init__(self, camera: "Camera", recorder: Recorder, frames: int | None = None):
        self.camera = camera
        self.recorder = recorder
        self.limit = frames
        self.frames = 0  # frames offered to the recorder
        self.last_frame_at = time.monotonic()
        self.error: RecordingError | None = None
        self.done = threading.Event()

    def put(self, frame: Frame) -> None:
        if self.done.is_set():
            return
        try:
            self.recorder.put(frame, counters_of(self.camera))
        except RecordingError as exc:  # the disk failed: the recording ends, the camera goes on
            self.error = exc
            self.done.set()
            return
        self.frames += 1
        self.last_frame_at = time.monotonic()
        if self.limit is not None and self.frames >= self.limit:
            self.done.set()


def record(camera: "Camera", path: str | Path, *, frames: int | None = None, seconds: float | None = None,
           progress: Callable[[Progress], None] | None = None, **recorder_options) -> RecorderStats:
    """Record ``camera`` to ``path`` until ``frames`` captures or ``seconds`` have gone by (or the
    stream stops); starts streaming if it was not, and stops it again then. No frame at all is a
    StreamStalledError saying why if it can (a trigger mode nothing triggers); the empty file is removed."""
    if frames is None and seconds is None:
        raise ConfigError("record needs a limit: frames or seconds")
    frames = None if frames is None else count_arg(frames, "frames", 1)
    seconds = None if seconds is None else timeout_arg(seconds, "seconds")
    if seconds == 0:
        raise ConfigError("seconds must be more than 0")
    if not isinstance(path, (str, Path)):
        raise ConfigError(f"record needs a file path, got {path!r}")
    unknown = sorted(set(recorder_options) - RECORDER_OPTIONS)
    if unknown:
        raise ConfigError(f"unknown recorder option {', '.join(unknown)}; known: {', '.join(sorted(RECORDER_OPTIONS))}")
    check_options(**recorder_options)  # all before the file is made or the camera asked
    if progress is not None and not callable(progress):
        raise ConfigError(f"progress must be a callable taking a Progress, or None, got {progress!r}")
    if os.path.lexists(path):  # the Recorder refuses too (exclusive create); said here before the camera is asked
        raise RecordingError(f"{path} already exists: a recording never replaces a file; remove it or give "
                             f"another path")
    started_here = not camera.streaming
    unit = describe(camera)
    recorder = Recorder(path, unit, **recorder_options)
    listener = RecordingListener(camera, recorder, frames)
    stall = max(camera.timeout, 2.0)  # streaming but no frame for this long: the recording ends
    camera.add_listener(listener)
    t0 = time.monotonic()
    next_report = t0 + PROGRESS_PERIOD
    try:
        if started_here:
            camera.start()
        listener.last_frame_at = time.monotonic()
        while not listener.done.wait(WAIT_STEP):
            now = time.monotonic()
            if (seconds is not None and now - t0 >= seconds) or now - listener.last_frame_at > stall:
                break
            camera.connection.check_alive()
            if progress is not None and now >= next_report:
                next_report = now + PROGRESS_PERIOD
                progress(_progress(recorder, listener.frames, now - t0))
    finally:
        camera.remove_listener(listener)
        if started_here and camera.alive:
            camera.stop()
        stats = recorder.close()
    if listener.error is not None:
        raise listener.error
    if listener.frames == 0:  # nothing to keep: the path is free for another try
        Path(path).unlink(missing_ok=True)
        raise StreamStalledError(f"no frame arrived in {time.monotonic() - t0:.1f} s of recording"
                                 f"{_why_no_frame(unit.config)}; {path} not kept")
    if progress is not None:
        progress(_progress(recorder, listener.frames, time.monotonic() - t0))
    return stats


def _why_no_frame(config: dict[str, int]) -> str:
    """Why a camera configured so sends no frame by itself, as the end of a sentence ("" if it should)."""
    mode = config.get("trigger_mode")
    if mode == TriggerMode.SOFTWARE:
        return (": the camera is in software-trigger mode (trigger_mode=software) and nothing triggered it "
                "(trigger_mode=free_run streams at fps)")
    if mode == TriggerMode.EXTERNAL:
        return ": the camera waits for external trigger pulses (trigger_mode=external) and none came"
    return ""


def _progress(recorder: Recorder, frames: int, dt: float) -> Progress:
    st = recorder.stats
    dt = max(dt, 1e-9)
    return Progress(frames, dt, frames / dt, st.camera_bytes / dt / 1e6, st.file_bytes / dt / 1e6,
                    LinkCounters(**{**st.counters.__dict__, "recorder_dropped": st.recorder_dropped}),
                    recorder.backlog_bytes / 1e6)
