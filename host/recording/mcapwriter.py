"""An MCAP writer for high-rate captures, built from the ``mcap`` library's record classes.

It writes what ``mcap.writer.Writer`` writes (chunks, message indexes, a summary with chunk and
metadata indexes, statistics and summary offsets) with three differences that recording needs:

* a chunk is a list of buffers (the planes themselves, not copies) until it is full; it is then
  zstd-compressed on a small thread pool at a chosen level (zstd releases the GIL) while the
  caller fills the next one; chunks still reach the file in order;
* each chunk is handed to the operating system as soon as it is written, and schemas, channels
  and metadata go out at once, outside chunks: a process killed at any moment leaves a file that
  reads up to its last complete chunk (``repair`` then rewrites its summary);
* a frame index (log time of every capture, an attachment) lets a reader seek by frame number.
"""
from __future__ import annotations

import collections
import contextlib
import numbers
import os
import struct
import zlib
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Sequence, Union

import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (Attachment, AttachmentIndex, Channel, Chunk, ChunkIndex, DataEnd, Footer, Header,
                          MessageIndex, Metadata, MetadataIndex, Schema, Statistics, SummaryOffset)
from mcap.well_known import Profile

from stereocam.protocol.errors import ConfigError

MAGIC = b"\x89MCAP0\r\n"
RECORD_SIZE_LIMIT = 1 << 30  # bytes of one MCAP record: a record claiming more is damage, not data
DEFAULT_CHUNK_BYTES = 4 << 20
MAX_CHUNK_BYTES = 64 << 20  # a reader refuses a chunk larger than this plus one capture (chunks.py)
DEFAULT_LEVEL = 1
MIN_LEVEL, MAX_LEVEL = -(1 << 17), zstandard.MAX_COMPRESSION_LEVEL  # zstd's ZSTD_minCLevel() .. ZSTD_maxCLevel()
MAX_THREADS = 64  # compression threads: more only wait for the file (chunks are written in order)


Buffers = Sequence[Union[bytes, memoryview]]
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log time, publish time


@dataclass
class _OpenChunk:
    """The chunk being filled: its records as a list of buffers, joined only when compressed."""

    pieces: list = field(default_factory=list)
    size: int = 0
    indexes: dict[int, MessageIndex] = field(default_factory=dict)
    start: int = 0
    end: int = 0
    messages: int = 0


def check_level(level: object) -> int:
    """``level`` if it is a zstd compression level (an integer from zstd's fastest to 22), else ConfigError."""
    if isinstance(level, bool) or not isinstance(level, int) or not MIN_LEVEL <= level <= MAX_LEVEL:
        raise ConfigError(f"zstd level must be an integer from {MIN_LEVEL} to {MAX_LEVEL}, got {level!r}")
    return level


def int_option(value: object, name: str, lo: int, hi: int | None = None) -> int:
    """``value`` as an int from ``lo`` to ``hi`` (numpy integers too; bool, floats and strings
    refused), else ConfigError naming ``name`` and the range."""
    if not isinstance(value, bool) and isinstance(value, numbers.Integral):
        number = int(value)
        if lo <= number and (hi is None or number <= hi):
            return number
    allowed = f"from {lo} to {hi}" if hi is not None else f"of at least {lo}"
    raise ConfigError(f"{name} must be an integer {allowed}, got {value!r}")


def _compress(pieces: Buffers, level: int) -> tuple[bytes, int]:
    """zstd frame and CRC-32 of the concatenated ``pieces`` (zstd and zlib release the GIL). One
    join, then zstd in one shot: faster than streaming the pieces through a compressor object."""
    raw = b"".join(pieces)
    return zstandard.ZstdCompressor(level=level).compress(raw), zlib.crc32(raw)


class ChunkedWriter:
    """Write an MCAP file: ``register_schema``/``register_channel``, ``add_message``, ``finish``."""

    def __init__(self, path: str | Path, *, profile: str = Profile.ROS2, library: str = "stereocam",
                 chunk_bytes: int = DEFAULT_CHUNK_BYTES, level: int = DEFAULT_LEVEL, threads: int = 2,
                 exclusive: bool = False):
        """``exclusive``: never replace a file (FileExistsError if ``path`` exists). Every option
        is checked (ConfigError) before the file is touched; a file created here and not started
        (a write failed) is removed again."""
        level = check_level(level)  # a bad level would otherwise fail at the first chunk
        chunk_bytes = int_option(chunk_bytes, "chunk_bytes", 1, MAX_CHUNK_BYTES)
        threads = int_option(threads, "threads", 1, MAX_THREADS)
        self._out: BinaryIO = open(path, "xb" if exclusive else "wb")  # closed by finish()
        try:
            self._start(profile, library, chunk_bytes, level, threads)
        except BaseException:
            self._out.close()
            if exclusive:  # ours: nothing of it is worth keeping
                with contextlib.suppress(OSError):
                    os.unlink(path)
            raise

    def _start(self, profile: str, library: str, chunk_bytes: int, level: int, threads: int) -> None:
        self._pos = 0
        self._chunk_bytes = chunk_bytes
        self._level = level
        self._pool = ThreadPoolExecutor(threads, thread_name_prefix="mcap-zstd")
        self._max_pending = 2 * threads
        self._pending: collections.deque[tuple[Future, _OpenChunk, int]] = collections.deque()
        self._chunk = _OpenChunk()
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._attachment_indexes: list[AttachmentIndex] = []
        self.stats = Statistics(message_count=0, schema_count=0, channel_count=0, attachment_count=0,
                                metadata_count=0, chunk_count=0, message_start_time=0, message_end_time=0,
                                channel_message_counts=collections.defaultdict(int))
        self._write(MAGIC)
        self._record(Header(profile=profile, library=library))

    @property
    def position(self) -> int:
        """Bytes written to the file so far."""
        return self._pos

    # -- records outside chunks ---------------------------------------------------------------
    def _write(self, data: bytes) -> None:
        self._out.write(data)
        self._pos += len(data)

    def _record(self, record) -> tuple[int, int]:
        """Write one record now (and hand it to the OS); returns its offset and length."""
        builder = RecordBuilder()
        record.write(builder)
        data = builder.end()
        offset = self._pos
        self._write(data)
        self._out.flush()
        return offset, len(data)

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema = Schema(id=len(self.schemas) + 1, name=name, encoding=encoding, data=data)
        self.schemas[schema.id] = schema
        self.stats.schema_count += 1
        self._record(schema)
        return schema.id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: dict[str, str] | None = None) -> int:
        channel = Channel(id=len(self.channels) + 1, topic=topic, message_encoding=message_encoding,
                          schema_id=schema_id, metadata=metadata or {})
        self.channels[channel.id] = channel
        self.stats.channel_count += 1
        self._record(channel)
        return channel.id

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        offset, length = self._record(Metadata(name=name, metadata=data))
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=length, name=name))
        self.stats.metadata_count += 1

    def add_attachment(self, name: str, media_type: str, data: bytes, log_time: int = 0) -> None:
        offset, length = self._record(Attachment(create_time=log_time, log_time=log_time, name=name,
                                                 media_type=media_type, data=data))
        self._attachment_indexes.append(AttachmentIndex(offset=offset, length=length, log_time=log_time,
                                                        create_time=log_time, data_size=len(data), name=name,
                                                        media_type=media_type))
        self.stats.attachment_count += 1

    # -- messages -----------------------------------------------------------------------------
    def add_message(self, channel_id: int, log_time: int, data: Buffers, publish_time: int, sequence: int = 0) -> None:
        """One message; ``data`` is its bytes as a sequence of buffers (kept, not copied, until written)."""
        c = self._chunk
        if c.messages == 0:
            c.start = c.end = log_time
        c.start, c.end = min(c.start, log_time), max(c.end, log_time)
        index = c.indexes.get(channel_id)
        if index is None:
            index = c.indexes[channel_id] = MessageIndex(channel_id=channel_id, records=[])
        index.records.append((log_time, c.size))
        length = sum(len(p) for p in data)
        # a Message record (MCAP spec): its fixed fields as mcap.records.Message writes them, then the data
        c.pieces.append(_MESSAGE_HEAD.pack(Opcode.MESSAGE, 22 + length, channel_id, sequence, log_time, publish_time))
        c.pieces.extend(data)
        c.size += _MESSAGE_HEAD.size + length
        c.messages += 1
        st = self.stats
        st.message_start_time = log_time if st.message_count == 0 else min(st.message_start_time, log_time)
        st.message_end_time = max(st.message_end_time, log_time)
        st.message_count += 1
        st.channel_message_counts[channel_id] += 1
        if c.size >= self._chunk_bytes:
            self._close_chunk()

    def _close_chunk(self) -> None:
        c, self._chunk = self._chunk, _OpenChunk()
        if c.messages == 0:
            return
        self._pending.append((self._pool.submit(_compress, c.pieces, self._level), c, c.size))
        self._drain(block=len(self._pending) > self._max_pending)

    def _drain(self, block: bool) -> None:
        """Write the compressed chunks that are ready, in order (waiting for the oldest if ``block``)."""
        while self._pending and (block or self._pending[0][0].done()):
            future, c, size = self._pending.popleft()
            data, crc = future.result()
            self._write_chunk(Chunk(message_start_time=c.start, message_end_time=c.end, uncompressed_size=size,
                                    uncompressed_crc=crc, compression="zstd", data=data), list(c.indexes.values()))
            block = False

    def _write_chunk(self, chunk: Chunk, indexes: list[MessageIndex]) -> None:
        """A chunk record and its message indexes, handed to the OS; remembered for the summary."""
        offset = self._pos
        builder = RecordBuilder()
        chunk.write(builder)
        length = builder.count
        offsets = {}
        for index in indexes:
            offsets[index.channel_id] = offset + builder.count
            index.write(builder)
        self._write(builder.end())
        self._out.flush()
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=chunk.message_start_time, message_end_time=chunk.message_end_time,
            chunk_start_offset=offset, chunk_length=length, message_index_offsets=offsets,
            message_index_length=self._pos - offset - length, compression=chunk.compression,
            compressed_size=len(chunk.data), uncompressed_size=chunk.uncompressed_size))
        self.stats.chunk_count += 1

    def copy_chunk(self, chunk: Chunk, indexes: list[MessageIndex]) -> None:
        """Take a chunk of another file as it is (compressed bytes, message indexes): joining files
        without decompressing them. Its channel ids must mean the same channels in this file."""
        self.flush()
        st = self.stats
        for index in indexes:
            if index.channel_id not in self.channels:
                raise ValueError(f"chunk refers to channel {index.channel_id}, not registered here")
            for log_time, _ in index.records:
                st.message_start_time = log_time if st.message_count == 0 else min(st.message_start_time, log_time)
                st.message_end_time = max(st.message_end_time, log_time)
                st.message_count += 1
            st.channel_message_counts[index.channel_id] += len(index.records)
        self._write_chunk(chunk, indexes)

    def flush(self) -> None:
        """Close the open chunk and write every chunk still being compressed."""
        self._close_chunk()
        while self._pending:
            self._drain(block=True)

    # -- end ----------------------------------------------------------------------------------
    def finish(self) -> None:
        """Write the summary (schemas, channels, statistics, indexes, offsets) and the footer."""
        self.flush()
        self._pool.shutdown()
        self._record(DataEnd(data_section_crc=0))
        summary_start = self._pos
        builder = RecordBuilder()
        offsets: list[SummaryOffset] = []
        groups = ((Opcode.SCHEMA, list(self.schemas.values())), (Opcode.CHANNEL, list(self.channels.values())),
                  (Opcode.STATISTICS, [self.stats]), (Opcode.CHUNK_INDEX, self._chunk_indexes),
                  (Opcode.ATTACHMENT_INDEX, self._attachment_indexes),
                  (Opcode.METADATA_INDEX, self._metadata_indexes))
        for opcode, records in groups:
            start = builder.count
            for record in records:
                record.write(builder)
            if records:
                offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + start,
                                             group_length=builder.count - start))
        offset_start = summary_start + builder.count
        for o in offsets:
            o.write(builder)
        summary = builder.end()
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, offset_start), zlib.crc32(summary))
        self._write(summary)
        footer = RecordBuilder()
        Footer(summary_start=summary_start, summary_offset_start=offset_start, summary_crc=crc).write(footer)
        self._write(footer.end())
        self._write(MAGIC)
        self._out.close()

    def abandon(self) -> None:
        """Stop without a summary (what a crash leaves; ``repair`` completes it)."""
        self._pool.shutdown(wait=False, cancel_futures=True)
        self._out.close()
