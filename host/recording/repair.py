"""Repair a recording cut short (SIGKILL, power loss): keep every complete chunk, rewrite the rest.

A killed recorder leaves the header, schemas, channels and metadata (written at once) and every
chunk it finished; the chunk being written and the summary are missing. ``repair`` reads the file
as a stream up to the first record that is cut off or fails its CRC, drops a trailing capture
that lost some of its messages, and writes a complete file (summary, chunk indexes, frame index)
next to it, then moves it into place atomically.
"""
from __future__ import annotations

import os
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import zstandard
from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory

from stereocam.protocol.params import Output

from . import schemas
from .mcapwriter import ChunkedWriter
from .recorder import FRAME_INDEX, FRAME_INDEX_TYPE, RecordingError

_CUT_SHORT = (McapError, EOFError, struct.error, zstandard.ZstdError, ValueError)


@dataclass(frozen=True)
class RepairReport:
    frames: int  # complete captures kept
    dropped_partial: int  # a trailing capture missing some messages (0 or 1)
    bytes_before: int
    bytes_after: int
    was_complete: bool  # the file already had its footer


def _records(path: Path) -> Iterator[Any]:
    """Records up to the first that is cut off or damaged (chunks opened into their messages)."""
    with open(path, "rb") as f:
        reader = StreamReader(f, skip_magic=False, emit_chunks=False, validate_crcs=True)
        try:
            yield from reader.records
        except _CUT_SHORT:
            return


def repair(path: str | Path, out: str | Path | None = None) -> RepairReport:
    """Rewrite ``path`` (or write ``out``) with a summary and indexes; see the module doc."""
    path = Path(path)
    out = Path(out) if out is not None else path
    if not path.is_file():
        raise RecordingError(f"{path}: no such file")
    tmp = out.with_name(out.name + ".repair-tmp")
    writer: ChunkedWriter | None = None
    channel_ids: dict[int, int] = {}
    schema_ids: dict[int, int] = {}
    capture_channel, decode = None, None
    group: list[Message] = []
    log_times: list[int] = []
    last_info = None
    summary_meta, other_meta, dropped, complete = None, [], 0, False

    def flush_group(final: bool) -> None:
        nonlocal group, last_info, dropped
        info = next((decode(m.data) for m in group if m.channel_id == capture_channel), None) if decode else None
        needed = 3 + bin(info.planes & int(Output.LEFT | Output.RIGHT | Output.DISPARITY)).count("1") if info else 0
        if final and (info is None or len(group) < needed):
            dropped += bool(group)
        else:
            for m in group:
                writer.add_message(channel_ids[m.channel_id], m.log_time, [m.data], m.publish_time, m.sequence)
            if info is not None:
                log_times.append(group[0].log_time)
                last_info = info
        group = []

    try:
        for record in _records(path):
            if isinstance(record, Header):
                writer = ChunkedWriter(tmp, profile=record.profile, library=record.library)
            elif writer is None:
                break
            elif isinstance(record, Schema) and record.id not in schema_ids:
                schema_ids[record.id] = writer.register_schema(record.name, record.encoding, record.data)
                if record.name == schemas.CAPTURE_INFO:
                    decode = DecoderFactory().decoder_for("cdr", record)
            elif isinstance(record, Channel) and record.id not in channel_ids:
                channel_ids[record.id] = writer.register_channel(record.topic, record.message_encoding,
                                                                 schema_ids.get(record.schema_id, 0), record.metadata)
                if record.topic == schemas.CAPTURE:
                    capture_channel = record.id
            elif isinstance(record, Message) and record.channel_id in channel_ids:
                if group and record.log_time != group[0].log_time:
                    flush_group(final=False)
                group.append(record)
            elif isinstance(record, Metadata):
                if record.name == "stereocam.summary":
                    summary_meta = dict(record.metadata)
                else:
                    other_meta.append(record)
            elif isinstance(record, Attachment) and record.name != FRAME_INDEX:
                writer.add_attachment(record.name, record.media_type, record.data, record.log_time)
            elif isinstance(record, Footer):
                complete = True
        if writer is None:
            raise RecordingError(f"{path} does not start with an MCAP header: nothing to repair")
        flush_group(final=True)
        writer.flush()
        for m in other_meta:
            writer.add_metadata(m.name, dict(m.metadata))
        if summary_meta is None:  # the recorder never got to write it: the last capture's counters
            counters = {k: str(getattr(last_info, k)) for k in ("link_lost", "link_incomplete", "host_queue_overflow",
                                                                 "device_dropped", "recorder_dropped")} \
                if last_info is not None else {}
            summary_meta = {"frames": str(len(log_times)), **counters, "repaired": "true"}
        writer.add_metadata("stereocam.summary", summary_meta)
        writer.add_attachment(FRAME_INDEX, FRAME_INDEX_TYPE, np.asarray(log_times, "<i8").tobytes())
        writer.finish()
        before = path.stat().st_size
        os.replace(tmp, out)
    except BaseException:
        if writer is not None:
            writer.abandon()
        tmp.unlink(missing_ok=True)
        raise
    return RepairReport(len(log_times), dropped, before, out.stat().st_size, complete)
