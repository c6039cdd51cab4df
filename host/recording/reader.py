"""Reading a recording back: the unit it came from, and its captures by frame number.

Seeking uses the file's own indexes: the frame index (log time of every capture) says when
capture ``i`` was logged, the summary's chunk indexes which chunk holds that instant; only that
chunk is read. Messages are decoded by the ``mcap`` reader and ``mcap-ros2-support``.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from mcap_ros2.decoder import DecoderFactory

from stereocam.calibration_io import StoredCalibration
from stereocam.frames import DisparityFormat, Frame, FrameStatus, StereoGeometry
from stereocam.protocol.calibration import StereoCalibration

from . import schemas
from .convert import disparity_from_float
from .recorder import FRAME_INDEX, RecordingError, UnitDescription


@dataclass
class RecordedCapture:
    """One capture as recorded: its planes as the camera sent them and its CaptureInfo."""

    index: int  # frame number in the recording, from 0
    log_time: int  # ns, the header stamp of all its messages
    info: Any  # the decoded stereocam_msgs/CaptureInfo (sequence, trigger_id, device_time_us, ...)
    left: np.ndarray | None
    right: np.ndarray | None
    disparity: np.ndarray | None  # int16, disparity * 16, exactly the camera's plane

    def to_frame(self) -> Frame:
        """The capture as the SDK's Frame (what ``get_frame`` returned while recording)."""
        i = self.info
        return Frame(i.sequence, i.trigger_id, i.device_time_us, i.host_time, self.left, self.right, self.disparity,
                     i.exposure_us, i.gain, i.width, i.height, i.rectified,
                     DisparityFormat(i.subpixel, i.min_disparity, i.num_disparities, i.invalid_disparity),
                     StereoGeometry(i.focal_px, i.cx, i.cy, i.baseline_m, i.calibration_id), FrameStatus(i.status))


def _plane(msg: Any, dtype: str) -> np.ndarray:
    data = bytes(msg.data)
    if len(data) != msg.height * msg.width * np.dtype(dtype).itemsize:
        raise ValueError(f"an image of {msg.width}x{msg.height} carries {len(data)} bytes")
    return np.frombuffer(data, dtype).reshape(msg.height, msg.width)


class DamagedRecordingError(RecordingError):
    """A frame of the recording cannot be read (bad chunk CRC, undecodable message); ``frame`` is its
    index: reading can go on from ``frame + 1``."""

    def __init__(self, message: str, frame: int):
        super().__init__(message)
        self.frame = frame


RECORD_SIZE_LIMIT = 1 << 30  # bytes of one MCAP record: a chunk header claiming more is damage, not data


class Recording:
    """An MCAP recording opened for reading (needs its summary: ``repair`` a crashed one first)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        try:
            self._file = open(self.path, "rb")  # noqa: SIM115 - closed by close()
            # every chunk's CRC is checked as it is read: a damaged frame is an error, never bad pixels
            self._reader = SeekingReader(self._file, validate_crcs=True, decoder_factories=[DecoderFactory()],
                                         record_size_limit=RECORD_SIZE_LIMIT)
            self.summary = self._reader.get_summary()
        except (OSError, McapError, ValueError, EOFError, struct.error) as exc:
            raise RecordingError(f"{self.path} is not a readable MCAP file: {exc}") from exc
        if self.summary is None or not self.summary.chunk_indexes and self.summary.statistics.message_count:
            self.close()
            raise RecordingError(f"{self.path} has no summary or index (was the recorder killed?); run "
                                 f"'stereocam recording repair {self.path}'")
        self.metadata = {m.name: dict(m.metadata) for m in self._reader.iter_metadata()}
        index = next((a for a in self._reader.iter_attachments() if a.name == FRAME_INDEX), None)
        if index is None:
            raise RecordingError(f"{self.path} has no frame index; run 'stereocam recording repair {self.path}'")
        if len(index.data) % 8:
            raise RecordingError(f"{self.path}: its frame index is damaged ({len(index.data)} bytes); "
                                 f"run 'stereocam recording repair {self.path}'")
        self.log_times = np.frombuffer(index.data, "<i8")

    # -- the unit ----------------------------------------------------------------------------
    @property
    def device(self) -> dict[str, str]:
        return self.metadata.get("stereocam.device", {})

    @property
    def config(self) -> dict[str, int]:
        return {k: int(v) for k, v in self.metadata.get("stereocam.config", {}).items()}

    @property
    def calibration(self) -> StoredCalibration | None:
        c = self.metadata.get("stereocam.calibration")
        if c is None:
            return None
        body = bytes.fromhex(c["body_hex"])
        return StoredCalibration(StereoCalibration.from_bytes(body), body, c["source"], int(c["generation"]),
                                 int(c["calibration_id"]))

    @property
    def unit(self) -> UnitDescription:
        return UnitDescription(self.device, self.config, self.calibration)

    @property
    def clock_offset_ns(self) -> int:
        """Host wall clock minus monotonic clock while recording (stamps = host time + this)."""
        return int(self.metadata.get("stereocam.recording", {}).get("clock_offset_ns", 0))

    def chunk_frame_starts(self) -> list[int]:
        """For each chunk in file order, the first frame whose stamp is at or after its start."""
        starts = sorted(c.message_start_time for c in self.summary.chunk_indexes)
        return sorted(set(int(i) for i in np.searchsorted(self.log_times, starts)) - {len(self)})

    @property
    def topics(self) -> dict[str, int]:
        """Topic → message count."""
        counts = self.summary.statistics.channel_message_counts
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
        return next(self.captures(index % len(self), index % len(self) + 1))

    def captures(self, start: int = 0, stop: int | None = None) -> Iterator[RecordedCapture]:
        """Captures ``start`` .. ``stop - 1`` in order; the chunks before ``start`` are not read."""
        stop = len(self) if stop is None else min(stop, len(self))
        if start >= stop:
            return
        t0, t1 = int(self.log_times[start]), int(self.log_times[stop - 1])
        messages = self._reader.iter_decoded_messages(starting_at=t0, ending_before=t1 + 1)
        parts: dict[str, Any] = {}
        index, current = start, None
        while True:
            try:
                item = next(messages, None)
                ready = None
                if current is not None and (item is None or item[2].log_time != current):
                    ready = self._assemble(index, current, parts)
            except Exception as exc:  # zstd, CDR, MCAP or shape errors of a damaged or hostile file
                raise DamagedRecordingError(f"{self.path}: frame {index} cannot be read ({type(exc).__name__}: "
                                            f"{exc}); the file is damaged", index) from exc
            if ready is not None:
                yield ready
                index, parts = index + 1, {}
            if item is None:
                return
            _, channel, message, decoded = item
            current = message.log_time
            parts[channel.topic] = decoded

    def _assemble(self, index: int, log_time: int, parts: dict[str, Any]) -> RecordedCapture:
        left, right, disp = parts.get(schemas.LEFT), parts.get(schemas.RIGHT), parts.get(schemas.DISPARITY_TOPIC)
        return RecordedCapture(index, log_time, parts.get(schemas.CAPTURE),
                               _plane(left, "u1") if left else None, _plane(right, "u1") if right else None,
                               disparity_from_float(_plane(disp.image, "<f4")) if disp else None)

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> "Recording":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
