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
from dataclasses import dataclass, field
from typing import Any, BinaryIO, Callable, Iterator

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Chunk, Footer, Header, McapRecord, Message, Metadata, Schema

from .chunks import Exact, chunk_limit, chunk_records
from .mcapwriter import MAGIC, RECORD_SIZE_LIMIT
from .recorder import CONFIG, RECORDING

_KNOWN = frozenset(int(op) for op in Opcode)
_MESSAGE_FIXED = 22  # channel id, sequence, log time, publish time
_HEAD = struct.Struct("<BQ")  # opcode, record length
# the records a repair copies; the rest (indexes, statistics, summary offsets, data end) it writes anew
_READERS: dict[int, Callable[[ReadDataStream], Any]] = {
    Opcode.HEADER: Header.read, Opcode.SCHEMA: Schema.read, Opcode.CHANNEL: Channel.read,
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
    # the most a chunk may hold: from the recording's metadata once read (written before any chunk)
    max_chunk_bytes: int = field(default_factory=lambda: chunk_limit({}, {}))
    _metadata: dict[str, dict[str, str]] = field(default_factory=dict, repr=False)

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
                records = _parse(opcode, body, self.max_chunk_bytes)
            except Exception:  # anything a damaged or hostile record makes the parsers raise
                if opcode == Opcode.CHUNK:
                    self.damaged_chunks += 1
                else:
                    self.damaged_records += 1
                continue
            for record in records:
                if isinstance(record, Metadata) and record.name in (CONFIG, RECORDING):
                    self._metadata[record.name] = dict(record.metadata)
                    meta = self._metadata
                    self.max_chunk_bytes = chunk_limit(meta.get(CONFIG, {}), meta.get(RECORDING, {}))
            yield from records
            if opcode == Opcode.FOOTER:
                self.complete = True
                return

    def _stop(self, pos: int, cut_short: bool) -> None:
        self.stopped_at, self.cut_short = pos, cut_short


def _parse(opcode: int, body: bytes, limit: int) -> list[McapRecord]:
    """The records in one record's ``body``: a chunk's records (bounded and CRC checked, see
    ``chunks``), or the record itself; nothing for records a repair writes anew. Raises on damage."""
    stream = Exact(io.BytesIO(body))
    if opcode == Opcode.CHUNK:
        chunk = Chunk.read(stream)
        if stream.count != len(body):
            raise ValueError("chunk fields disagree with its record length")
        return chunk_records(chunk, limit)
    if opcode == Opcode.MESSAGE:
        if len(body) < _MESSAGE_FIXED:
            raise ValueError("message record too short")
        return [Message.read(stream, len(body))]
    read = _READERS.get(opcode)
    return [] if read is None else [read(stream)]
