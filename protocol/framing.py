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
import bisect
import logging
import math
import struct
import time
import zlib
from dataclasses import dataclass, field

from .crc_range import CrcIndex

MAGIC = b"STOC"
VERSION_MAJOR = 1
VERSION_MINOR = 3
HEADER_LEN = 20
MAX_HEADER_LEN = 64
TRAILER_LEN = 4
MAX_PAYLOAD = 1 << 20  # hard v1 limit; a device may advertise less

DEVICE_MESSAGE_TIMEOUT = 1.0  # s: a device abandons a request frame not complete this long after its header
HOST_MESSAGE_TIMEOUT = 5.0  # s: the host's limit (a 128 KiB chunk takes 1.4 s at 921600 baud)
STAMP_GRAIN = 0.001  # s: chunks arriving closer together than this share one arrival stamp (SPEC §3)

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
    message_timeouts: int = 0  # valid header whose frame did not complete within message_timeout: rescanned

    @property
    def dropped(self) -> int:
        """Frames lost to corruption or policy."""
        return (self.header_crc_errors + self.bad_headers + self.payload_crc_errors + self.oversize
                + self.unsupported_version + self.message_timeouts)

    def as_dict(self) -> dict[str, int]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass
class Decoder:
    """Incremental decoder: feed arbitrary chunks, get complete packets back (SPEC §3).

    Resynchronises after garbage or corruption by scanning for the next magic whose header CRC
    checks out; its buffer never holds more than one maximum-size frame plus one read chunk.
    ``message_timeout`` (float seconds, None: never) bounds how long a frame whose header has
    arrived may take to complete; after it the frame is abandoned like a corrupt one. Time is the
    ``now`` given to ``feed`` (default ``time.monotonic()``); an idle receiver calls ``expire``.
    A header's wait runs from the arrival of its last byte (each chunk is stamped on arrival,
    SPEC §3), never from when a rescan reached it: stray headers cost T in all, not T each.
    Work per input byte is bounded (SPEC §3.1): a rescan inside a rejected frame reuses the
    checksums already computed instead of checksumming the same bytes again.
    """

    max_payload: int = MAX_PAYLOAD
    stats: DecoderStats = field(default_factory=DecoderStats)
    message_timeout: float | None = None
    _buf: bytearray = field(default_factory=bytearray, repr=False)
    _base: int = field(default=0, repr=False)  # absolute stream offset of _buf[0]
    _arrival_ends: list[int] = field(default_factory=list, repr=False)  # absolute end offset of each stamp's bytes
    _arrival_times: list[float] = field(default_factory=list, repr=False)  # when those bytes arrived
    _pending: float | None = field(default=None, repr=False)  # arrival of the header being waited on
    _failed: tuple[int, int] = field(default=(-1, -1), repr=False)  # payload range of the last rejected frame
    _index: CrcIndex | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not 0 <= self.max_payload <= MAX_PAYLOAD:
            raise ValueError(f"max_payload must be within 0..{MAX_PAYLOAD}")
        t = self.message_timeout
        if t is not None and not (isinstance(t, (int, float)) and math.isfinite(t) and t > 0):
            raise ValueError(f"message_timeout must be a finite number of seconds > 0, got {t!r}")

    @property
    def buffered(self) -> int:
        return len(self._buf)

    def expire(self, now: float | None = None) -> list[Packet]:
        """For an idle receiver: abandon a partial frame older than ``message_timeout`` and return
        the packets the bytes behind it complete."""
        return self.feed(b"", now)

    def feed(self, data: bytes | bytearray | memoryview, now: float | None = None) -> list[Packet]:
        """Consume ``data``; return the packets completed by it (possibly none)."""
        self.stats.bytes_in += len(data)
        if data and self.message_timeout is not None:
            self._stamp(len(data), time.monotonic() if now is None else now)
        self._buf += data
        out: list[Packet] = []
        buf = self._buf
        pos = 0
        end = len(buf)
        st = self.stats
        self._pending = None
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
            if buf[pos + 18] | buf[pos + 19] << 8 != binascii.crc_hqx(buf[pos:pos + 18], 0xFFFF):
                st.header_crc_errors += 1  # (the cheapest check first: a magic in garbage costs this much)
                pos += 1
                continue
            _, major, minor, hlen, flags, mtype, rid, plen, _ = _HEAD.unpack_from(buf, pos)
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
                if self._timed_out(self._base + pos, now):
                    st.message_timeouts += 1
                    pos += 1
                    continue
                if self.message_timeout is not None:
                    self._pending = self._header_arrival(self._base + pos)
                break
            (crc,) = _CRC32.unpack_from(buf, pos + hlen + plen)
            if crc != self._payload_crc(pos + HEADER_LEN, pos + hlen + plen):
                st.payload_crc_errors += 1
                _log.info("payload CRC error in a type 0x%04x packet (request id %d, %d payload bytes); "
                          "dropped, resyncing", mtype, rid, plen)
                pos += 1
                continue
            payload = bytes(buf[pos + hlen:pos + hlen + plen])
            out.append(Packet(mtype, rid, flags, payload, (major, minor)))
            st.packets += 1
            pos += total
        if pos:
            self._discard(pos)
        return out

    def _stamp(self, n: int, now: float) -> None:
        """Record the arrival of the next ``n`` bytes. Chunks within STAMP_GRAIN of the last stamp
        share it (their bytes count as arrived up to STAMP_GRAIN early), so a byte-at-a-time
        stream keeps few stamps."""
        end = self._base + len(self._buf) + n
        if self._arrival_times and now - self._arrival_times[-1] < STAMP_GRAIN:
            self._arrival_ends[-1] = end
        else:
            self._arrival_ends.append(end)
            self._arrival_times.append(now)

    def _timed_out(self, offset: int, now: float | None) -> bool:
        """Whether the partial frame at absolute ``offset`` has waited longer than message_timeout
        since its header's last byte arrived."""
        if self.message_timeout is None:
            return False
        now = time.monotonic() if now is None else now
        return now - self._header_arrival(offset) > self.message_timeout

    def _header_arrival(self, offset: int) -> float:
        """When the last header byte of the frame at absolute ``offset`` arrived."""
        return self._arrival_times[bisect.bisect_right(self._arrival_ends, offset + HEADER_LEN - 1)]

    @property
    def waiting_since(self) -> float | None:
        """Arrival time of the header whose frame the decoder is waiting to complete (None: not
        waiting, or no message timeout)."""
        return self._pending

    def _payload_crc(self, a: int, b: int) -> int:
        """CRC-32 of ``_buf[a:b]``. A range overlapping bytes already checksummed for a rejected
        frame goes through the CRC index, so no byte is checksummed more than twice."""
        base, buf = self._base, self._buf
        lo, hi = base + a, base + b
        if self._index is not None and lo < self._index.tip:
            return self._index.crc(buf, base, lo, hi)
        self._index = None
        if lo < self._failed[1]:  # inside the last rejected frame: index from here on
            self._index = CrcIndex(lo)
            return self._index.crc(buf, base, lo, hi)
        with memoryview(buf) as mv:
            crc = zlib.crc32(mv[a:b])
        self._failed = (lo, hi)  # kept in case it fails; a delivered frame is never rescanned
        return crc

    def _discard(self, pos: int) -> None:
        """Drop ``_buf[:pos]`` (consumed), keeping the CRC index usable for what remains."""
        cut = self._base + pos
        if self._index is not None:
            if self._index.tip <= cut:
                self._index = None
            else:
                self._index.drop_before(self._buf, self._base, cut)
        del self._buf[:pos]
        self._base = cut
        k = bisect.bisect_right(self._arrival_ends, cut)
        if k:
            del self._arrival_ends[:k], self._arrival_times[:k]
