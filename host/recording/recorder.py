"""The recorder: frames in on the caller's thread, an MCAP file written on its own thread.

``put`` never blocks: a frame that finds the bounded queue full is not written and counted as a
recorder drop, apart from the camera's and the link's own drops; every CaptureInfo message
carries all those counters so far, and the summary metadata the final ones.
"""
from __future__ import annotations

import collections
import contextlib
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from mcap.well_known import MessageEncoding, SchemaEncoding

import stereocam
from stereocam.calibration_io import StoredCalibration
from stereocam.frames import Frame
from stereocam.protocol.errors import StereoCamError

from . import convert, schemas
from .mcapwriter import DEFAULT_CHUNK_BYTES, DEFAULT_LEVEL, MAX_CHUNK_BYTES, MAX_THREADS, ChunkedWriter, check_level, \
    int_option

DEFAULT_QUEUE_BYTES = 512 << 20
FRAME_INDEX = "stereocam/frame_index"  # attachment: int64 log time (ns) of every capture, in order
FRAME_INDEX_TYPE = "application/x-stereocam-frame-index-int64le"
DEVICE, CONFIG, CALIBRATION, RECORDING, SUMMARY = ("stereocam.device", "stereocam.config", "stereocam.calibration",
                                                   "stereocam.recording", "stereocam.summary")
"""The metadata records of a recording: the unit, its configuration and calibration, the recording, its summary."""


class RecordingError(StereoCamError):
    """The recording could not be written (disk full, file not writable, ...) or read."""


class DamagedRecordingError(RecordingError):
    """Part of a recording cannot be read (bad chunk CRC, undecodable message, a metadata value that
    is not what it should be); ``frame`` is the index of the frame that cannot be read, if it is one
    (reading can go on from ``frame + 1``), else None."""

    def __init__(self, message: str, frame: int | None = None):
        super().__init__(message)
        self.frame = frame

    def __reduce__(self):  # pickled whole (a Dask worker's error reaches the client with its frame)
        return type(self), (str(self), self.frame)


@dataclass(frozen=True)
class UnitDescription:
    """What the file says about the unit: INFO, configuration, stored calibration."""

    info: dict[str, str]
    config: dict[str, int]
    calibration: StoredCalibration | None


@dataclass
class RecorderStats:
    frames: int = 0  # captures written
    recorder_dropped: int = 0  # captures the writer could not take (queue full)
    camera_bytes: int = 0  # plane bytes as the camera sent them, written
    file_bytes: int = 0  # bytes in the file so far (compressed)
    counters: convert.LinkCounters = field(default_factory=convert.LinkCounters)


def check_options(*, queue_bytes: object = DEFAULT_QUEUE_BYTES, level: object = DEFAULT_LEVEL, threads: object = 2,
                  chunk_bytes: object = DEFAULT_CHUNK_BYTES) -> dict[str, int]:
    """The recorder's options as ints, each checked (ConfigError naming the option and its range)."""
    return {"queue_bytes": int_option(queue_bytes, "queue_bytes", 1), "level": check_level(level),
            "threads": int_option(threads, "threads", 1, MAX_THREADS),
            "chunk_bytes": int_option(chunk_bytes, "chunk_bytes", 1, MAX_CHUNK_BYTES)}


def _frame_bytes(frame: Frame) -> int:
    return sum(p.nbytes for p in (frame.left, frame.right, frame.disparity, frame.confidence) if p is not None)


class Recorder:
    """Write captures of one unit to an MCAP file (ROS 2 profile). ``put`` frames, then ``close``."""

    def __init__(self, path: str | Path, unit: UnitDescription, *, queue_bytes: int = DEFAULT_QUEUE_BYTES,
                 level: int = DEFAULT_LEVEL, threads: int = 2, chunk_bytes: int = DEFAULT_CHUNK_BYTES,
                 clock_offset_ns: int | None = None, extra_metadata: dict[str, dict[str, str]] | None = None):
        """``clock_offset_ns``: host wall clock minus monotonic clock for the stamps (default: now;
        re-writing a recording passes the original's so every stamp stays the same)."""
        self.path = Path(path)
        options = check_options(queue_bytes=queue_bytes, level=level, threads=threads, chunk_bytes=chunk_bytes)
        self._chunk_bytes = options["chunk_bytes"]
        try:  # never over an existing file (a failed recording must not cost the one it replaced);
            # written in place, not renamed at the end: a killed recorder leaves a file to repair
            self._writer = ChunkedWriter(self.path, library=f"stereocam {stereocam.__version__}",
                                         level=options["level"], threads=options["threads"],
                                         chunk_bytes=self._chunk_bytes, exclusive=True)
        except FileExistsError as exc:
            raise RecordingError(f"{self.path} already exists: a recording never replaces a file; remove it "
                                 f"or give another path") from exc
        except OSError as exc:
            raise RecordingError(f"cannot write {self.path}: {exc}") from exc
        try:
            self._start(unit, options["queue_bytes"], clock_offset_ns, extra_metadata)
        except BaseException as exc:  # no recorder, no file: the path is free for another try
            self._writer.abandon()
            with contextlib.suppress(OSError):
                self.path.unlink()
            if isinstance(exc, OSError):
                raise RecordingError(f"cannot write {self.path}: {exc}") from exc
            raise

    def _start(self, unit: UnitDescription, queue_bytes: int, clock_offset_ns: int | None,
               extra_metadata: dict[str, dict[str, str]] | None) -> None:
        """The file's head (schemas, channels, the unit), then the writer thread."""
        self.unit = unit
        self.stats = RecorderStats()
        self.clock_offset_ns = time.time_ns() - time.monotonic_ns() if clock_offset_ns is None else clock_offset_ns
        self._encoders = {name: schemas.encoder(name) for name in set(schemas.TOPICS.values())}
        ids = {name: self._writer.register_schema(name, SchemaEncoding.ROS2, schemas.msgdef(name).encode())
               for name in self._encoders}
        self._schema_ids = ids
        self._channels = {topic: self._writer.register_channel(topic, MessageEncoding.CDR, ids[name])
                          for topic, name in schemas.TOPICS.items()}
        self._write_unit(unit)
        for name, data in (extra_metadata or {}).items():
            self._writer.add_metadata(name, data)
        self._infos: dict[tuple[int, int, int, bool], tuple[dict, dict]] = {}
        self._log_times: list[int] = []
        self._upstream_dropped = 0
        self._queue: collections.deque[tuple[Frame, convert.LinkCounters]] = collections.deque()
        self._queued_bytes = 0
        self._queue_bytes = queue_bytes
        self._cond = threading.Condition()
        self._closing = False
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="stereocam-recorder", daemon=True)
        self._thread.start()

    def _write_unit(self, unit: UnitDescription) -> None:
        w = self._writer
        w.add_metadata(DEVICE, unit.info)
        w.add_metadata(CONFIG, {k: str(v) for k, v in unit.config.items()})
        cal = unit.calibration
        if cal is not None:
            w.add_metadata(CALIBRATION, {
                "body_hex": cal.body.hex(), "source": cal.source, "generation": str(cal.generation),
                "calibration_id": str(cal.calibration_id)})
        w.add_metadata(RECORDING, {
            "clock_offset_ns": str(self.clock_offset_ns), "sdk_version": stereocam.__version__,
            "chunk_bytes": str(self._chunk_bytes),  # bounds what a reader decompresses (chunks.py)
            "stamps": "header stamps and log times: the capture's device time mapped to the host's monotonic "
                      "clock, plus clock_offset_ns (host wall clock at the start of the recording)",
            "disparity": "stereo_msgs/DisparityImage 32FC1 in px, delta_d 1/16: round(d*16) is the camera's "
                         "int16 Q4 plane; invalid = min_disparity - 1"})

    # -- caller's side ------------------------------------------------------------------------
    def put(self, frame: Frame, counters: convert.LinkCounters = convert.LinkCounters()) -> bool:
        """Queue ``frame`` for writing; False (and a recorder drop) if the queue is full."""
        if self._error is not None:
            raise RecordingError(f"writing {self.path} failed: {self._error}") from self._error
        size = _frame_bytes(frame)
        with self._cond:
            if self._closing:
                raise RecordingError(f"recorder for {self.path} is closed")
            if self._queued_bytes + size > self._queue_bytes and self._queue:
                self.stats.recorder_dropped += 1
                return False
            self._queue.append((frame, counters))
            self._queued_bytes += size
            self._cond.notify()
        return True

    def put_wait(self, frame: Frame, counters: convert.LinkCounters = convert.LinkCounters()) -> None:
        """Queue ``frame``, waiting for room (benchmarks and re-writing files: nothing is dropped)."""
        with self._cond:
            while self._queue and self._queued_bytes + _frame_bytes(frame) > self._queue_bytes:
                self._cond.wait(0.1)
        self.put(frame, counters)

    @property
    def backlog_bytes(self) -> int:
        return self._queued_bytes

    def close(self) -> RecorderStats:
        """Write what is queued, then the summary; returns the final figures."""
        with self._cond:
            self._closing = True
            self._cond.notify_all()
        self._thread.join()
        if self._error is not None:
            raise RecordingError(f"writing {self.path} failed: {self._error}") from self._error
        return self.stats

    def __enter__(self) -> "Recorder":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- writer thread ------------------------------------------------------------------------
    def _run(self) -> None:
        try:
            while True:
                with self._cond:
                    while not self._queue and not self._closing:
                        self._cond.wait()
                    if not self._queue:
                        break
                    frame, counters = self._queue.popleft()
                self._write(frame, counters)
                with self._cond:
                    self._queued_bytes -= _frame_bytes(frame)
                    self._cond.notify_all()
            self._finish()
        except BaseException as exc:  # reported to the caller by put/close
            self._error = exc
            self._writer.abandon()

    def _write(self, frame: Frame, counters: convert.LinkCounters) -> None:
        ns = int(frame.host_time * 1e9) + self.clock_offset_ns
        if self._log_times and ns <= self._log_times[-1]:
            ns = self._log_times[-1] + 1  # log times stay unique and increasing: one per capture
        self._upstream_dropped = counters.recorder_dropped  # an earlier writer's drops (re-written files)
        counters = convert.LinkCounters(**{**counters.__dict__, "recorder_dropped": counters.recorder_dropped
                                           + self.stats.recorder_dropped})
        msgs = [(schemas.CAPTURE, convert.capture_info(ns, frame, counters))]
        key = (frame.geometry.calibration_id, frame.width, frame.height, frame.rectified)
        if key not in self._infos:
            cal = self.unit.calibration.calibration if self.unit.calibration and key[0] else None
            self._infos[key] = convert.camera_infos(cal, frame.width, frame.height, frame.rectified)
        for topic, body, side in ((schemas.LEFT_INFO, self._infos[key][0], "left"),
                                  (schemas.RIGHT_INFO, self._infos[key][1], "right")):
            msgs.append((topic, {**body, "header": convert.header(ns, schemas.FRAME_IDS[side])}))
        for topic, body in msgs:
            self._writer.add_message(self._channels[topic], ns, [self._encoders[schemas.TOPICS[topic]](body)], ns,
                                     frame.sequence)
        blobs = []
        for topic, side, plane in ((schemas.LEFT, "left", frame.left), (schemas.RIGHT, "right", frame.right),
                                   (schemas.CONFIDENCE_TOPIC, "left", frame.confidence)):
            if plane is not None:
                body = convert.image(ns, schemas.FRAME_IDS[side], plane)
                blobs.append((topic, body, body, convert.blob(plane)))
        if frame.disparity is not None:
            body = convert.disparity(ns, frame)
            disparity = convert.blob(convert.disparity_to_float(frame))
            blobs.append((schemas.DISPARITY_TOPIC, body, body["image"], disparity))
        if frame.confidence is not None and schemas.CONFIDENCE_TOPIC not in self._channels:
            self._channels[schemas.CONFIDENCE_TOPIC] = self._writer.register_channel(
                schemas.CONFIDENCE_TOPIC, MessageEncoding.CDR, self._schema_ids[schemas.IMAGE])
        for topic, body, slot, data in blobs:
            encoded = schemas.encode_with_blob(self._encoders[schemas.TOPICS.get(topic, schemas.IMAGE)], body, slot,
                                               data)
            self._writer.add_message(self._channels[topic], ns, encoded, ns, frame.sequence)
        self._log_times.append(ns)
        st = self.stats
        st.frames += 1
        st.camera_bytes += _frame_bytes(frame)
        st.file_bytes = self._writer.position
        st.counters = counters

    def _finish(self) -> None:
        self._writer.flush()
        self._writer.add_attachment(FRAME_INDEX, FRAME_INDEX_TYPE, np.asarray(self._log_times, "<i8").tobytes())
        st = self.stats
        self._writer.add_metadata(SUMMARY, {
            "frames": str(st.frames), "camera_bytes": str(st.camera_bytes),
            **{k: str(v) for k, v in asdict(st.counters).items()},
            "recorder_dropped": str(self._upstream_dropped + st.recorder_dropped)})
        self._writer.finish()
        st.file_bytes = self._writer.position
