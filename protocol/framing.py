"""Frame layer: header + payload + CRC-32 trailer, and the incremental resynchronising decoder.

Layout (little-endian, protocol/SPEC.md §2):

    0  magic "STOC"     4  ver_major u8   5  ver_minor u8   6  header_len u8   7  flags u8
    8  type u16         10 request_id u16  12 payload_len u32 16 reserved u16  18 header_crc u16
    header_len .. +payload_len  payload,   then u32 CRC-32 over bytes [20, end of payload)

The header CRC is CRC-16/CCITT-FALSE (binascii.crc_hqx, init 0xFFFF) over bytes 0..17. A length
is never trusted before the header CRC checks out.
"""
from __future__ import annotations

import binascii
import logging
import struct
import zlib
from dataclasses import dataclass, field

MAGIC = b"STOC"
VERSION_MAJOR = 1
VERSION_MINOR = 1
HEADER_LEN = 20
MAX_HEADER_LEN = 64
TRAILER_LEN = 4
MAX_PAYLOAD = 1 << 20  # hard v1 limit; a device may advertise less

FLAG_RESEND = 0x01  # request: this is a retry of the same request id

_HEAD = struct.Struct("<4sBBBBHHIH")  # the 18 bytes the header CRC covers
_CRC16 = struct.Struct("<H")
_CRC32 = struct.Struct("<I")
_log = logging.getLogger(__name__)


def header_crc(first18: bytes | memoryview) -> int:
    """CRC-16/CCITT-FALSE of the first 18 header bytes."""
    return binascii.crc_hqx(first18, 0xFFFF)


def encode_frame(msg_type: int, request_id: int, payload: bytes | memoryview = b"", flags: int = 0) -> bytes:
    """One complete frame on the wire."""
    n = len(payload)
    if n > MAX_PAYLOAD:
        raise ValueError(f"payload of {n} bytes exceeds MAX_PAYLOAD {MAX_PAYLOAD}")
    head = _HEAD.pack(MAGIC, VERSION_MAJOR, VERSION_MINOR, HEADER_LEN, flags, msg_type, request_id, n, 0)
    return b"".join((head, _CRC16.pack(header_crc(head)), payload, _CRC32.pack(zlib.crc32(payload))))


@dataclass(frozen=True, slots=True)
class Packet:
    """One decoded frame: header fields and the raw payload."""

    msg_type: int
    request_id: int
    flags: int
    payload: bytes
    version: tuple[int, int] = (VERSION_MAJOR, VERSION_MINOR)


@dataclass
class DecoderStats:
    """Running counters; nothing the decoder drops goes uncounted."""

    bytes_in: int = 0
    packets: int = 0
    garbage_bytes: int = 0  # bytes skipped while hunting for a header
    header_crc_errors: int = 0
    bad_headers: int = 0  # header CRC fine but fields impossible (header_len)
    payload_crc_errors: int = 0
    oversize: int = 0  # valid header announcing more than max_payload: rescanned, never buffered
    unsupported_version: int = 0  # valid header of another major version: rescanned

    @property
    def dropped(self) -> int:
        """Frames lost to corruption or policy."""
        return self.header_crc_errors + self.bad_headers + self.payload_crc_errors + self.oversize + self.unsupported_version

    def as_dict(self) -> dict[str, int]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass
class Decoder:
    """Incremental decoder: feed arbitrary chunks, get complete packets back.

    Resynchronises after garbage or corruption by scanning for the next magic whose header CRC
    checks out; its buffer never holds more than one maximum-size frame plus one read chunk.
    """

    max_payload: int = MAX_PAYLOAD
    stats: DecoderStats = field(default_factory=DecoderStats)
    _buf: bytearray = field(default_factory=bytearray, repr=False)

    def __post_init__(self) -> None:
        if not 0 <= self.max_payload <= MAX_PAYLOAD:
            raise ValueError(f"max_payload must be within 0..{MAX_PAYLOAD}")

    @property
    def buffered(self) -> int:
        return len(self._buf)

    def feed(self, data: bytes | bytearray | memoryview) -> list[Packet]:
        """Consume ``data``; return the packets completed by it (possibly none)."""
        self.stats.bytes_in += len(data)
        self._buf += data
        out: list[Packet] = []
        buf = self._buf
        pos = 0
        end = len(buf)
        st = self.stats
        while True:
            i = buf.find(MAGIC, pos)
            if i < 0:
                keep = max(pos, end - (len(MAGIC) - 1))  # a partial magic may sit at the end
                st.garbage_bytes += keep - pos
                pos = keep
                break
            st.garbage_bytes += i - pos
            pos = i
            if end - pos < HEADER_LEN:
                break
            _, major, minor, hlen, flags, mtype, rid, plen, _ = _HEAD.unpack_from(buf, pos)
            (hcrc,) = _CRC16.unpack_from(buf, pos + 18)
            if hcrc != header_crc(memoryview(buf)[pos:pos + 18]):
                st.header_crc_errors += 1
                pos += 1
                continue
            if not HEADER_LEN <= hlen <= MAX_HEADER_LEN:
                st.bad_headers += 1
                pos += 1
                continue
            if major != VERSION_MAJOR or plen > self.max_payload:
                # never buffer what we will not accept: count it and rescan from the next byte,
                # so a stray valid-looking header cannot blind the decoder for a megabyte
                if major != VERSION_MAJOR:
                    st.unsupported_version += 1
                else:
                    st.oversize += 1
                pos += 1
                continue
            total = hlen + plen + TRAILER_LEN
            if end - pos < total:
                break
            body = memoryview(buf)[pos + HEADER_LEN:pos + hlen + plen]
            (crc,) = _CRC32.unpack_from(buf, pos + hlen + plen)
            if crc != zlib.crc32(body):
                body.release()
                st.payload_crc_errors += 1
                _log.info("payload CRC error in a type 0x%04x packet (request id %d, %d payload bytes); "
                          "dropped, resyncing", mtype, rid, plen)
                pos += 1
                continue
            payload = bytes(body[hlen - HEADER_LEN:])
            body.release()
            out.append(Packet(mtype, rid, flags, payload, (major, minor)))
            st.packets += 1
            pos += total
        if pos:
            del buf[:pos]
        return out
