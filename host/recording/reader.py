"""Reading a recording back: the unit it came from, and its captures by frame number.

Seeking uses the file's own indexes: the frame index (log time of every capture) says when
capture ``i`` was logged, the summary's chunk indexes which chunk holds that instant; only that
chunk is read. Messages are decoded by the ``mcap`` reader and ``mcap-ros2-support``.
"""
from __future__ import annotations

import io
import os

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Message, Statistics
from mcap.summary import Summary
from mcap_ros2.decoder import DecoderFactory

from stereocam.calibration_io import StoredCalibration
from stereocam.input_files import open_regular
from stereocam.frames import DisparityFormat, Frame, FrameStatus, StereoGeometry
from stereocam.protocol.errors import ConfigError
from stereocam.protocol.params import BY_NAME

from . import metadata as meta
from . import schemas
from .chunks import Exact, chunk_limit, chunk_records
from .convert import disparity_from_float
from .mcapwriter import MAGIC, RECORD_SIZE_LIMIT
from .recorder import FRAME_INDEX, DamagedRecordingError, RecordingError, UnitDescription

_CHUNK_FIELDS = 8 + 8 + 8 + 4 + 4 + 1024 + 8  # a chunk record's fields besides its data (compression name <= 1 KiB)

__all__ = ["Recording", "RecordedCapture", "DamagedRecordingError", "RecordingError"]


@dataclass
class RecordedCapture:
    """One capture as recorded: its planes as the camera sent them and its CaptureInfo."""

    index: int  # frame number in the recording, from 0
    log_time: int  # ns, the header stamp of all its messages
    info: Any  # the decoded stereocam_msgs/CaptureInfo (sequence, trigger_id, device_time_us, ...)
    left: np.ndarray | None
    right: np.ndarray | None
    disparity: np.ndarray | None  # int16, disparity * 16, exactly the camera's plane
    confidence: np.ndarray | None = None  # uint8, the camera's confidence plane (SPEC §5.3) if recorded

    def to_frame(self) -> Frame:
        """The capture as the SDK's Frame (what ``get_frame`` returned while recording)."""
        i = self.info
        return Frame(i.sequence, i.trigger_id, i.device_time_us, i.host_time, self.left, self.right, self.disparity,
                     i.exposure_us, i.gain, i.width, i.height, i.rectified,
                     DisparityFormat(i.subpixel, i.min_disparity, i.num_disparities, i.invalid_disparity),
                     StereoGeometry(i.focal_px, i.cx, i.cy, i.baseline_m, i.calibration_id), FrameStatus(i.status),
                     confidence=self.confidence)


def _plane(msg: Any, dtype: str) -> np.ndarray:
    data = bytes(msg.data)
    if len(data) != msg.height * msg.width * np.dtype(dtype).itemsize:
        raise ValueError(f"an image of {msg.width}x{msg.height} carries {len(data)} bytes")
    return np.frombuffer(data, dtype).reshape(msg.height, msg.width)




def _check_capture(cap: RecordedCapture) -> None:
    """ValueError unless ``cap`` is a capture a unit could have sent: every CaptureInfo field of this
    recorder's schema, a known status, a frame size within the unit's range that its planes have."""
    info = cap.info
    missing = [f for f in schemas.CAPTURE_INFO_FIELDS if not hasattr(info, f)]
    if missing:
        raise ValueError(f"its CaptureInfo has no field {missing[0]!r} (a schema that is not this recorder's)")
    if info.status not in {s.value for s in FrameStatus}:
        raise ValueError(f"capture status {info.status!r} is not one of {[s.value for s in FrameStatus]}")
    for name in ("width", "height"):
        why = BY_NAME[name].check(getattr(info, name))
        if why:
            raise ValueError(f"frame size: {why}")
    for plane in (cap.left, cap.right, cap.disparity, cap.confidence):
        if plane is not None and plane.shape != (info.height, info.width):
            raise ValueError(f"a plane of {plane.shape[1]}x{plane.shape[0]} in a {info.width}x{info.height} capture")


class Recording:
    """An MCAP recording opened for reading (needs its summary: ``repair`` a crashed one first)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._file = open_regular(self.path, what="recording", error=RecordingError)
        try:
            self._open()
        except BaseException:
            self._file.close()
            raise

    def _open(self) -> None:
        """The summary, metadata and frame index; RecordingError for a file that lacks them."""
        path, repair = self.path, f"run 'stereocam recording repair {self.path}'"
        try:
            head = self._file.read(len(MAGIC))
            self._file.seek(0)
        except OSError as exc:
            raise RecordingError(f"cannot read {path}: {exc.strerror or exc}") from exc
        if head != MAGIC:
            raise RecordingError(f"{path} is not an MCAP file (it does not start with MCAP's magic bytes)")
        try:
            # every chunk's CRC is checked as it is read: a damaged frame is an error, never bad pixels
            self._reader = SeekingReader(self._file, validate_crcs=True, decoder_factories=[DecoderFactory()],
                                         record_size_limit=RECORD_SIZE_LIMIT)
            summary = self._reader.get_summary()
        except Exception as exc:  # whatever a cut-off or damaged end makes the reader raise
            raise RecordingError(f"{path} is truncated or damaged: an MCAP file without a valid summary and footer "
                                 f"at its end (was the recorder killed?); {repair}") from exc
        self._size = os.fstat(self._file.fileno()).st_size
        self._decoder_factory = DecoderFactory()
        self._decoders: dict[int, Callable[[bytes], Any]] = {}
        if summary is None or summary.statistics is None \
                or not summary.chunk_indexes and summary.statistics.message_count:
            raise RecordingError(f"{path} has no summary or index (was the recorder killed?); {repair}")
        self.summary: Summary = summary
        self._statistics: Statistics = summary.statistics
        try:
            self.metadata = {m.name: dict(m.metadata) for m in self._reader.iter_metadata()}
            index = next((a for a in self._reader.iter_attachments() if a.name == FRAME_INDEX), None)
        except Exception as exc:  # offsets or records of a damaged summary
            raise DamagedRecordingError(f"{path}: its metadata or attachments cannot be read ({type(exc).__name__}: "
                                        f"{exc}); {repair}") from exc
        self._chunk_limit = chunk_limit(self.metadata.get(meta.CONFIG, {}), self.metadata.get(meta.RECORDING, {}))
        if index is None:
            raise RecordingError(f"{path} has no frame index; {repair}")
        if len(index.data) % 8:
            raise DamagedRecordingError(f"{path}: its frame index is damaged ({len(index.data)} bytes); {repair}")
        self.log_times = np.frombuffer(index.data, "<i8")
        if np.any(np.diff(self.log_times) <= 0):
            raise DamagedRecordingError(f"{path}: its frame index is damaged (times not increasing); {repair}")
        counts = self._statistics.channel_message_counts
        captures = sum(counts.get(cid, 0) for cid, ch in self.summary.channels.items() if ch.topic == schemas.CAPTURE)
        if captures != len(self.log_times):
            raise DamagedRecordingError(f"{path}: its frame index lists {len(self.log_times)} frames but the file "
                                        f"holds {captures} captures; the file is damaged; {repair}")

    # -- the unit: each value checked when asked for (a damaged one is a DamagedRecordingError --
    # naming its field, and fails only what needs it: the frames still read) ---------------------
    @property
    def device(self) -> dict[str, str]:
        """The unit's INFO as recorded (model, serial, firmware_version, ...; empty if not recorded)."""
        return dict(self.metadata.get(meta.DEVICE, {}))

    @property
    def config(self) -> dict[str, int]:
        return meta.config(self.path, self.metadata)

    @cached_property
    def calibration(self) -> StoredCalibration | None:
        return meta.calibration(self.path, self.metadata)

    @property
    def summary_counts(self) -> dict[str, int]:
        """The recorder's final figures: frames, camera_bytes and the drop counters, those the file has."""
        return meta.summary_counts(self.path, self.metadata)

    @property
    def unit(self) -> UnitDescription:
        return UnitDescription(self.device, self.config, self.calibration)

    @property
    def clock_offset_ns(self) -> int:
        """Host wall clock minus monotonic clock while recording (stamps = host time + this)."""
        return meta.clock_offset_ns(self.path, self.metadata)

    def chunk_frame_starts(self) -> list[int]:
        """For each chunk in file order, the first frame whose stamp is at or after its start."""
        starts = sorted(c.message_start_time for c in self.summary.chunk_indexes)
        return sorted(set(int(i) for i in np.searchsorted(self.log_times, starts)) - {len(self)})

    @property
    def topics(self) -> dict[str, int]:
        """Topic → message count."""
        counts = self._statistics.channel_message_counts
        return {ch.topic: counts.get(cid, 0) for cid, ch in self.summary.channels.items()}

    @property
    def duration_s(self) -> float:
        return float(self.log_times[-1] - self.log_times[0]) / 1e9 if len(self.log_times) else 0.0

    # -- captures ----------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.log_times)

    def capture(self, index: int) -> RecordedCapture:
        """Capture ``index`` (from 0; negative counts from the end), reading only its chunk."""
        if not -len(self) <= index < len(self):
            raise IndexError(f"frame {index} outside a recording of {len(self)} frames")
        for cap in self.captures(index % len(self), index % len(self) + 1):
            return cap
        raise DamagedRecordingError(f"{self.path}: frame {index % len(self)} cannot be read; the file is damaged",
                                    index % len(self))  # not reached: captures() raises for a missing frame

    def captures(self, start: int = 0, stop: int | None = None) -> Iterator[RecordedCapture]:
        """Captures ``start`` .. ``stop - 1`` in order (both from 0, not negative); the chunks before
        ``start`` are not read. A frame of the index that cannot be read is a DamagedRecordingError."""
        if start < 0 or stop is not None and stop < 0:
            raise ConfigError(f"frames are numbered from 0: start {start}, stop {stop} (negative)")
        stop = len(self) if stop is None else min(stop, len(self))
        return self._captures(start, stop)

    def _captures(self, start: int, stop: int) -> Iterator[RecordedCapture]:
        if start >= stop:
            return
        t0, t1 = int(self.log_times[start]), int(self.log_times[stop - 1])
        messages = self._messages(t0, t1)
        parts: dict[str, Any] = {}
        index, current = start, None
        while index < stop:
            try:
                item = next(messages, None)
                ready = None
                if current is not None and (item is None or item[1].log_time != current):
                    ready = self._assemble(index, current, parts)
            except Exception as exc:  # zstd, CDR, MCAP or shape errors of a damaged or hostile file
                raise self._damaged(index, f"{type(exc).__name__}: {exc}") from exc
            if ready is not None:
                yield ready
                index, parts = index + 1, {}
            if item is None:
                break
            channel, message, decoded = item
            current = message.log_time
            parts[channel.topic] = decoded
        if index < stop:
            raise self._damaged(index, "the frame index lists it, the file holds no messages for it")

    def _messages(self, t0: int, t1: int) -> Iterator[tuple[Channel, Message, Any]]:
        """The messages logged from ``t0`` to ``t1`` (ns, both included), decoded, in time order, read
        from the chunks that hold them; each chunk bounded (``chunks``): damage raises."""
        indexes = sorted((c for c in self.summary.chunk_indexes if c.message_start_time <= t1
                          and c.message_end_time >= t0), key=lambda c: (c.message_start_time, c.chunk_start_offset))
        for index in indexes:
            records = chunk_records(self._chunk_at(index.chunk_start_offset), self._chunk_limit)
            messages = sorted((r for r in records if isinstance(r, Message) and t0 <= r.log_time <= t1),
                              key=lambda m: m.log_time)
            for m in messages:
                channel = self.summary.channels.get(m.channel_id)
                if channel is None:
                    raise ValueError(f"a message on channel {m.channel_id}, which the file does not define")
                yield channel, m, self._decoder(channel)(m.data)

    def _chunk_at(self, offset: int) -> Chunk:
        """The chunk record at ``offset``, read only if its length fits the limit and the file."""
        self._file.seek(offset)
        head = self._file.read(9)
        if len(head) != 9 or head[0] != Opcode.CHUNK:
            raise ValueError(f"no chunk at byte {offset}")
        length = int.from_bytes(head[1:], "little")
        # zstd never grows data by more than a few bytes per 128 KiB block: 1/64 is ample
        if length > self._chunk_limit + self._chunk_limit // 64 + _CHUNK_FIELDS or offset + 9 + length > self._size:
            raise ValueError(f"the chunk at byte {offset} claims {length} bytes")
        body = self._file.read(length)
        stream = Exact(io.BytesIO(body))
        chunk = Chunk.read(stream)
        if stream.count != len(body):
            raise ValueError(f"the chunk at byte {offset}: its fields disagree with its record length")
        return chunk

    def _decoder(self, channel: Channel) -> Callable[[bytes], Any]:
        decoder = self._decoders.get(channel.id)
        if decoder is None:
            schema = self.summary.schemas.get(channel.schema_id)
            decoder = self._decoder_factory.decoder_for(channel.message_encoding, schema) if schema else None
            if decoder is None:
                raise ValueError(f"channel {channel.topic!r}: no decoder for its {channel.message_encoding!r} "
                                 f"messages")
            self._decoders[channel.id] = decoder
        return decoder

    def _damaged(self, index: int, why: str) -> DamagedRecordingError:
        return DamagedRecordingError(f"{self.path}: frame {index} cannot be read ({why}); the file is damaged", index)

    def _assemble(self, index: int, log_time: int, parts: dict[str, Any]) -> RecordedCapture:
        if log_time != self.log_times[index]:
            raise ValueError(f"messages stamped {log_time} where the frame index says {int(self.log_times[index])}")
        if parts.get(schemas.CAPTURE) is None:
            raise ValueError(f"no {schemas.CAPTURE} message")
        left, right, disp = parts.get(schemas.LEFT), parts.get(schemas.RIGHT), parts.get(schemas.DISPARITY_TOPIC)
        cap = RecordedCapture(index, log_time, parts[schemas.CAPTURE],
                              _plane(left, "u1") if left else None, _plane(right, "u1") if right else None,
                              disparity_from_float(_plane(disp.image, "<f4")) if disp else None,
                              _plane(conf, "u1") if (conf := parts.get(schemas.CONFIDENCE_TOPIC)) else None)
        _check_capture(cap)
        return cap

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> "Recording":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
