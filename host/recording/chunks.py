"""Chunks opened within bounds: a hostile file must not make a reader allocate or parse more than
a chunk of its own recording can hold.

The bound comes from the recording itself: the recorder closes a chunk once it holds
``chunk_bytes`` (recorded in its metadata), so no chunk holds more than that plus one capture of
the recorded frame size (clamped to the largest frame a unit sends). A chunk declaring more is
damage; zstd decompresses as a stream into at most the declared size, whatever its frame header
claims; only schema, channel and message records may be inside.
"""
from __future__ import annotations

import io
import zlib
from typing import Mapping

import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, McapRecord, Message, Schema

from stereocam.protocol.params import BY_NAME

from .mcapwriter import DEFAULT_CHUNK_BYTES, MAX_CHUNK_BYTES

CAPTURE_PLANE_BYTES = 1 + 1 + 4  # left, right (mono8) and disparity (float32) per pixel
CAPTURE_OVERHEAD = 64 << 10  # CaptureInfo, CameraInfos and the messages' own fields, generously
_MESSAGE_FIXED = 22  # channel id, sequence, log time, publish time


class Exact(ReadDataStream):
    """A record's fields read from its body: a field running past the body is an error, not short."""

    def read(self, length: int) -> bytes:
        data = super().read(length) if length > 0 else b""
        if len(data) != length:
            raise EOFError(f"a field of {length} bytes runs past its record")
        return data


def _clamped(config: Mapping[str, str], name: str) -> int:
    """The recorded ``name`` (width, height) within what a unit can send; the largest if unreadable."""
    param = BY_NAME[name]
    try:
        return min(max(int(str(config.get(name, param.hi)), 10), param.lo), param.hi)
    except ValueError:
        return param.hi


def chunk_limit(config: Mapping[str, str], recording: Mapping[str, str]) -> int:
    """The most uncompressed bytes a chunk of this recording can hold (``config`` and ``recording``:
    its metadata records of those names, as recorded)."""
    try:
        target = int(str(recording.get("chunk_bytes", DEFAULT_CHUNK_BYTES)), 10)
    except ValueError:
        target = DEFAULT_CHUNK_BYTES
    target = min(max(target, 1), MAX_CHUNK_BYTES)
    return target + _clamped(config, "width") * _clamped(config, "height") * CAPTURE_PLANE_BYTES + CAPTURE_OVERHEAD


def chunk_data(chunk: Chunk, limit: int) -> bytes:
    """The uncompressed bytes of ``chunk`` (CRC checked), never more than ``limit`` nor than it
    declares; ValueError for a chunk that declares more, decompresses to another size or fails its CRC."""
    n = chunk.uncompressed_size
    if n > limit:
        raise ValueError(f"a chunk declares {n} bytes, more than the {limit} a chunk of this recording can hold")
    if chunk.compression == "":
        data = bytes(chunk.data)
    elif chunk.compression == "zstd":
        dctx = zstandard.ZstdDecompressor(max_window_size=1 << min(max(20, (limit - 1).bit_length()), 27))
        out = bytearray()
        try:
            with dctx.stream_reader(io.BytesIO(chunk.data), read_across_frames=True) as reader:
                while len(out) <= n:
                    piece = reader.read(n + 1 - len(out))
                    if not piece:
                        break
                    out += piece
        except zstandard.ZstdError as exc:  # a damaged frame, or one asking for a window over the limit
            raise ValueError(f"a chunk does not decompress: {exc}") from exc
        data = bytes(out)
    else:
        raise ValueError(f"a chunk compressed with {chunk.compression!r} (recordings use zstd)")
    if len(data) != n:
        raise ValueError(f"a chunk holds {'more than ' if len(data) > n else ''}{len(data)} bytes, declares {n}")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise ValueError("a chunk fails its CRC")
    return data


def chunk_records(chunk: Chunk, limit: int) -> list[McapRecord]:
    """The schemas, channels and messages of ``chunk`` (see ``chunk_data``); any other record inside
    is damage."""
    data = chunk_data(chunk, limit)
    inner = Exact(io.BytesIO(data))
    records: list[McapRecord] = []
    while inner.count < len(data):
        opcode, length = inner.read1(), inner.read8()
        body = Exact(io.BytesIO(inner.read(length)))
        if opcode == Opcode.MESSAGE:
            if length < _MESSAGE_FIXED:
                raise ValueError("message record too short")
            records.append(Message.read(body, length))
        elif opcode == Opcode.SCHEMA:
            records.append(Schema.read(body))
        elif opcode == Opcode.CHANNEL:
            records.append(Channel.read(body))
        else:
            raise ValueError(f"record opcode {opcode:#x} inside a chunk")
    return records
