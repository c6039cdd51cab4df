"""A recording read as a stream of records that tolerates damage: what ``repair`` reads.

A record whose length can be trusted (a known opcode, a length that fits in the file) is read
whole; if its contents are damaged (a chunk that fails its CRC or does not decompress, a record
that does not parse) it is skipped and counted, and the scan goes on with the record after it.
Only a record whose length cannot be trusted ends the scan: one that runs past the end of the file
(the file was cut short), or one with an unknown opcode or an absurd length (the rest is unreadable).
"""
from __future__ import annotations

import io
import struct
from dataclasses import dataclass
from typing import BinaryIO, Iterator

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Chunk, Footer, Header, McapRecord, Message, Metadata, Schema
from mcap.stream_reader import get_chunk_data_stream

from .mcapwriter import MAGIC, RECORD_SIZE_LIMIT

_KNOWN = frozenset(int(op) for op in Opcode)
_HEAD = struct.Struct("<BQ")  # opcode, record length
# the records a repair copies; the rest (indexes, statistics, summary offsets, data end) it writes anew
_READERS = {Opcode.HEADER: Header.read, Opcode.SCHEMA: Schema.read, Opcode.CHANNEL: Channel.read,
            Opcode.METADATA: Metadata.read, Opcode.ATTACHMENT: Attachment.read, Opcode.FOOTER: Footer.read}


@dataclass
class Scan:
    """Reads ``records`` of a file of ``size`` bytes; afterwards, what it found."""

    size: int
    damaged_chunks: int = 0  # chunks skipped: CRC, decompression or their records damaged
    damaged_records: int = 0  # other records skipped: they did not parse
    complete: bool = False  # the footer was reached
    cut_short: bool = False  # the file ends without a footer (inside a record or after one)
    stopped_at: int | None = None  # offset of the record the scan stopped at (None: footer or end of file)

    @property
    def unreadable_bytes(self) -> int:
        """Bytes from where the scan had to stop to the end of the file (what was not read)."""
        return 0 if self.stopped_at is None else self.size - self.stopped_at

    def records(self, f: BinaryIO) -> Iterator[McapRecord]:
        """The records of ``f`` in file order, chunks opened into their messages; nothing if ``f``
        does not start with MCAP's magic."""
        if f.read(len(MAGIC)) != MAGIC:
            self.stopped_at = 0
            return
        pos = len(MAGIC)
        while True:
            head = f.read(_HEAD.size)
            if not head:
                self.cut_short = True  # at a record boundary, but no footer
                return
            if len(head) < _HEAD.size:
                self._stop(pos, cut_short=True)
                return
            opcode, length = _HEAD.unpack(head)
            if opcode not in _KNOWN or length > RECORD_SIZE_LIMIT:
                self._stop(pos, cut_short=False)
                return
            if pos + _HEAD.size + length > self.size:
                self._stop(pos, cut_short=True)
                return
            body = f.read(length)
            pos += _HEAD.size + length
            try:
                records = _parse(opcode, body)
            except Exception:  # anything a damaged or hostile record makes the parsers raise
                if opcode == Opcode.CHUNK:
                    self.damaged_chunks += 1
                else:
                    self.damaged_records += 1
                continue
            yield from records
            if opcode == Opcode.FOOTER:
                self.complete = True
                return

    def _stop(self, pos: int, cut_short: bool) -> None:
        self.stopped_at, self.cut_short = pos, cut_short


class _Exact(ReadDataStream):
    """A record's fields read from its body: a field running past the body is an error, not short."""

    def read(self, length: int) -> bytes:
        data = super().read(length) if length > 0 else b""
        if len(data) != length:
            raise EOFError(f"a field of {length} bytes runs past its record")
        return data


_MESSAGE_FIXED = 22  # channel id, sequence, log time, publish time
_IN_CHUNK = {Opcode.SCHEMA: Schema.read, Opcode.CHANNEL: Channel.read}


def _parse(opcode: int, body: bytes, readers: dict = _READERS) -> list[McapRecord]:
    """The records in one record's ``body``: a chunk's records (CRC checked), or the record itself;
    nothing for records a repair writes anew. Raises on anything damaged."""
    stream = _Exact(io.BytesIO(body))
    if opcode == Opcode.CHUNK and readers is _READERS:
        chunk = Chunk.read(stream)
        if stream.count != len(body):
            raise ValueError("chunk fields disagree with its record length")
        return _chunk_records(chunk)
    if opcode == Opcode.MESSAGE:
        if len(body) < _MESSAGE_FIXED:
            raise ValueError("message record too short")
        return [Message.read(stream, len(body))]
    read = readers.get(opcode)
    return [] if read is None else [read(stream)]


def _chunk_records(chunk: Chunk) -> list[McapRecord]:
    """The messages (and schemas, channels) of ``chunk``, whose CRC must match."""
    if chunk.uncompressed_size > RECORD_SIZE_LIMIT:
        raise ValueError(f"chunk claims {chunk.uncompressed_size} bytes")
    stream, n = get_chunk_data_stream(chunk, validate_crc=True)
    if n != chunk.uncompressed_size:
        raise ValueError(f"chunk holds {n} bytes, says {chunk.uncompressed_size}")
    inner = _Exact(io.BytesIO(stream.read(n) if n else b""))
    records: list[McapRecord] = []
    while inner.count < n:
        opcode, length = inner.read1(), inner.read8()
        records += _parse(opcode, inner.read(length), _IN_CHUNK)
    return records
