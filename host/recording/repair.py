"""Repair a recording cut short (SIGKILL, power loss) or damaged: keep every readable capture.

A killed recorder leaves the header, schemas, channels and metadata (written at once) and every
chunk it finished; the chunk being written and the summary are missing. ``repair`` reads the file
as a stream (``scan``): a chunk that fails its CRC is skipped and counted and reading goes on; only
a record whose length cannot be trusted ends the reading. Captures that lost some of their
messages (at the cut, or beside a skipped chunk) are dropped. It writes a complete file (summary,
chunk indexes, frame index) next to the target and moves it into place; repairing in place keeps
the original beside it (``FILE.damaged``), so a repair never loses a byte.
"""
from __future__ import annotations

import errno
import os
import uuid
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Callable

import numpy as np
from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap_ros2.decoder import DecoderFactory

from stereocam.input_files import open_regular
from stereocam.protocol.params import Output

from . import schemas
from .mcapwriter import ChunkedWriter
from .recorder import FRAME_INDEX, FRAME_INDEX_TYPE, SUMMARY, RecordingError
from .scan import Scan

_PLANES = int(Output.LEFT | Output.RIGHT | Output.DISPARITY | Output.CONFIDENCE)
_COUNTERS = ("link_lost", "link_incomplete", "host_queue_overflow", "device_dropped", "recorder_dropped")


@dataclass(frozen=True)
class RepairReport:
    frames: int  # complete captures kept
    dropped_partial: int  # captures dropped because some of their messages were lost
    bytes_before: int
    bytes_after: int
    was_complete: bool  # the file had its footer
    damaged_chunks: int = 0  # chunks that failed their CRC (or did not decompress): skipped
    damaged_records: int = 0  # other records that did not parse: skipped
    cut_short: bool = False  # the file ended early (no footer)
    stopped_at: int | None = None  # where a record's length could not be trusted: nothing after it was read
    unreadable_bytes: int = 0  # bytes from ``stopped_at`` to the end of the file
    original: Path | None = None  # where the original file was kept (a repair in place)

    def line(self) -> str:
        """One line for people: what was kept, what was damaged, where the original is."""
        said = [f"{self.frames} frames kept"]
        if self.damaged_chunks:
            said.append(f"{self.damaged_chunks} chunks damaged and skipped")
        if self.damaged_records:
            said.append(f"{self.damaged_records} other records damaged and skipped")
        if self.cut_short:
            said.append("the file was cut short (no footer: was the recorder killed?)")
        elif self.stopped_at is not None:
            said.append(f"damaged at byte {self.stopped_at}: its last {self.unreadable_bytes} bytes could not be read")
        elif self.was_complete and not (self.damaged_chunks or self.damaged_records):
            said.append("the file was complete")
        if self.dropped_partial:
            said.append(f"{self.dropped_partial} captures missing some of their messages dropped")
        text = ", ".join(said) + f"; {self.bytes_before} -> {self.bytes_after} bytes"
        return text + (f"; the original is kept as {self.original}" if self.original else "")


class _Rewrite:
    """The records of the damaged file in, whole captures out to ``writer``."""

    def __init__(self) -> None:
        self.writer: ChunkedWriter | None = None
        self.channel_ids: dict[int, int] = {}
        self.schema_ids: dict[int, int] = {}
        self.capture_channel: int | None = None
        self.decode: Callable[[bytes], SimpleNamespace] | None = None
        self.group: list[Message] = []
        self.log_times: list[int] = []
        self.last_info: SimpleNamespace | None = None
        self.summary_meta: dict[str, str] | None = None
        self.other_meta: list[Metadata] = []
        self.dropped = 0

    def add(self, record: object, tmp: Path) -> bool:
        """Take one record; False once there is nothing more to take (no MCAP header first)."""
        if isinstance(record, Header):
            if self.writer is None:
                self.writer = ChunkedWriter(tmp, profile=record.profile, library=record.library, exclusive=True)
            return True
        if self.writer is None:
            return False
        if isinstance(record, Schema) and record.id not in self.schema_ids:
            self.schema_ids[record.id] = self.writer.register_schema(record.name, record.encoding, record.data)
            if record.name == schemas.CAPTURE_INFO:
                self.decode = DecoderFactory().decoder_for("cdr", record)
        elif isinstance(record, Channel) and record.id not in self.channel_ids:
            self.channel_ids[record.id] = self.writer.register_channel(
                record.topic, record.message_encoding, self.schema_ids.get(record.schema_id, 0), record.metadata)
            if record.topic == schemas.CAPTURE:
                self.capture_channel = record.id
        elif isinstance(record, Message) and record.channel_id in self.channel_ids:
            if self.group and record.log_time != self.group[0].log_time:
                self.flush_group()
            self.group.append(record)
        elif isinstance(record, Metadata):
            if record.name == SUMMARY:
                self.summary_meta = dict(record.metadata)
            else:
                self.other_meta.append(record)
        elif isinstance(record, Attachment) and record.name != FRAME_INDEX:
            self.writer.add_attachment(record.name, record.media_type, record.data, record.log_time)
        return True

    def _info(self, group: list[Message]) -> SimpleNamespace | None:
        """The decoded CaptureInfo of ``group``, or None (missing or undecodable)."""
        capture = [m for m in group if m.channel_id == self.capture_channel]
        if self.decode is None or len(capture) != 1:
            return None
        try:
            return self.decode(capture[0].data)
        except Exception:  # a damaged message: the capture is not whole
            return None

    def flush_group(self) -> None:
        """Write the current capture if it is whole (CaptureInfo and one message per topic it needs)."""
        group, self.group = self.group, []
        if not group:
            return
        info = self._info(group)
        needed = 3 + bin(int(info.planes) & _PLANES).count("1") if info is not None else 0
        if info is None or len(group) != needed or len({m.channel_id for m in group}) != needed:
            self.dropped += 1
            return
        assert self.writer is not None  # a group is only taken after the header
        for m in group:
            self.writer.add_message(self.channel_ids[m.channel_id], m.log_time, [m.data], m.publish_time, m.sequence)
        self.log_times.append(group[0].log_time)
        self.last_info = info

    def finish(self) -> None:
        """Metadata, the summary metadata (counters from the last capture if the recorder never wrote
        it), the frame index, the MCAP summary."""
        w = self.writer
        assert w is not None, "finish after the header"
        self.flush_group()
        w.flush()
        for m in self.other_meta:
            w.add_metadata(m.name, dict(m.metadata))
        summary = self.summary_meta
        if summary is None:  # the recorder never got to write it: the last capture's counters
            summary = {k: str(getattr(self.last_info, k)) for k in _COUNTERS} if self.last_info is not None else {}
        w.add_metadata(SUMMARY, {**summary, "frames": str(len(self.log_times)), "repaired": "true"})
        w.add_attachment(FRAME_INDEX, FRAME_INDEX_TYPE, np.asarray(self.log_times, "<i8").tobytes())
        w.finish()


def _keep(path: Path) -> Path:
    """A new name beside ``path`` that now also holds its contents (a hard link where the file system
    has them, else ``path`` renamed): FILE.damaged, FILE.damaged.1, ..."""
    for n in range(1000):
        kept = path.with_name(path.name + ".damaged" + (f".{n}" if n else ""))
        try:
            os.link(path, kept)
            return kept
        except FileExistsError:
            continue
        except OSError:
            if os.path.lexists(kept):
                continue
            os.rename(path, kept)
            return kept
    raise RecordingError(f"cannot keep the original of {path}: too many {path.name}.damaged files beside it")


def repair(path: str | Path, out: str | Path | None = None) -> RepairReport:
    """Rewrite ``path`` (the original kept as ``path.damaged``) or write ``out`` (a new file) with a
    summary and indexes; see the module doc."""
    path = Path(path)
    out = path if out is None else Path(out)
    in_place = out == path or path.exists() and out.exists() and os.path.samefile(path, out)
    if not in_place and os.path.lexists(out):
        raise RecordingError(f"{out} already exists: repair writes a new file (or give no --out to repair in place)")
    if not in_place and not out.parent.is_dir():  # before the input is read; named as given, not by the temporary file
        raise FileNotFoundError(errno.ENOENT, f"no folder {str(out.parent)!r} to write into", str(out))
    # a name of its own, created exclusively: an existing file (or a link) there is never written or removed
    tmp = out.with_name(f".{out.name}.{uuid.uuid4().hex[:12]}.repair-tmp")
    rewrite = _Rewrite()
    try:
        with open_regular(path, what="recording", error=RecordingError) as f:
            scan = Scan(os.fstat(f.fileno()).st_size)
            for record in scan.records(f):
                if not rewrite.add(record, tmp):
                    break
            if rewrite.writer is None:
                raise RecordingError(f"{path} does not start with an MCAP header: nothing to repair")
            rewrite.finish()
        kept = _keep(path) if in_place else None
        os.replace(tmp, out)
    except BaseException as exc:
        if rewrite.writer is not None:  # the temporary file is ours only if the writer created it
            rewrite.writer.abandon()
            tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError) and not isinstance(exc, FileExistsError) and str(exc.filename) == str(tmp):
            raise type(exc)(exc.errno, exc.strerror, str(out)) from exc  # the folder refused it: named as given
        raise
    return RepairReport(len(rewrite.log_times), rewrite.dropped, scan.size, out.stat().st_size, scan.complete,
                        scan.damaged_chunks, scan.damaged_records, scan.cut_short, scan.stopped_at,
                        scan.unreadable_bytes, kept)
