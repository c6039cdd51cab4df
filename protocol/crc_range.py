"""CRC-32 of any byte range of a stream without checksumming that range again.

zlib's CRC-32 is linear: with ``v(x)`` the CRC-32 of the stream's bytes from some origin up to
absolute position ``x``, the CRC-32 of the bytes ``[a, b)`` is ``v(b) ^ Z(b - a, v(a))``, where
``Z(n, .)`` is the 32x32 bit matrix "feed n zero bytes" (as in zlib's crc32_combine).
``CrcIndex`` keeps ``v`` at checkpoints at most ``STEP`` bytes apart, so the CRC of any range it
covers costs at most ``2 * STEP`` bytes of CRC plus one ``Z`` (at most 23 table steps), however
long the range. The decoder uses it to resynchronise inside a long rejected frame (SPEC §3).
"""
from __future__ import annotations

import zlib
from bisect import bisect_right

STEP = 64  # bytes between checkpoints
_M = 0xFFFFFFFF
_LEVELS = 23  # Z(2**k) for k < 23: ranges up to 8 MiB
_tables: list[tuple[list[int], list[int], list[int], list[int]]] = []


def _zero1(v: int) -> int:
    """One zero byte fed into register ``v`` (zlib works on the complemented register)."""
    return _M ^ zlib.crc32(b"\0", _M ^ v)


def _apply(t: tuple[list[int], list[int], list[int], list[int]], v: int) -> int:
    return t[0][v & 255] ^ t[1][(v >> 8) & 255] ^ t[2][(v >> 16) & 255] ^ t[3][v >> 24]


def _byte_tables(cols: list[int]) -> tuple[list[int], list[int], list[int], list[int]]:
    out = []
    for j in range(4):
        t = [0] * 256
        for b in range(1, 256):
            low = b & -b
            t[b] = t[b ^ low] ^ cols[8 * j + low.bit_length() - 1]
        out.append(t)
    return out[0], out[1], out[2], out[3]


def _build() -> None:
    """Tables of Z(2**k), built on first use (only adversarial streams need them), about 20 ms."""
    cols = [_zero1(1 << i) for i in range(32)]
    for _ in range(_LEVELS):
        t = _byte_tables(cols)
        _tables.append(t)
        cols = [_apply(t, c) for c in cols]


def zero_shift(v: int, n: int) -> int:
    """``Z(n, v)``: the CRC register ``v`` after ``n`` zero bytes (0 <= n < 2**23)."""
    if not 0 <= n < 1 << _LEVELS:
        raise ValueError(f"range of {n} bytes outside 0..{(1 << _LEVELS) - 1}")
    if not _tables:
        _build()
    while n:
        low = n & -n
        v = _apply(_tables[low.bit_length() - 1], v)
        n ^= low
    return v


def range_crc(v_a: int, v_b: int, n: int) -> int:
    """CRC-32 of the ``n`` bytes between two prefix values ``v_a`` (at a) and ``v_b`` (at a + n)."""
    return v_b ^ zero_shift(v_a, n)


class CrcIndex:
    """Prefix CRC-32 values over ``[start, tip)`` of a stream, at most STEP bytes apart.

    Positions are absolute stream offsets; ``buf`` is the caller's buffer and ``base`` the absolute
    offset of its first byte. Every byte is checksummed once when ``extend`` first covers it.
    """

    def __init__(self, start: int):
        self._pos = [start]
        self._val = [0]

    @property
    def tip(self) -> int:
        return self._pos[-1]

    def extend(self, buf: bytearray, base: int, end: int) -> None:
        p, v = self._pos[-1], self._val[-1]
        with memoryview(buf) as mv:
            while p < end:
                q = min(p + STEP, end)
                v = zlib.crc32(mv[p - base:q - base], v)
                p = q
                self._pos.append(p)
                self._val.append(v)

    def prefix(self, buf: bytearray, base: int, x: int) -> int:
        """``v(x)`` for ``start <= x <= tip``, from the nearest checkpoint below (<= STEP bytes)."""
        i = bisect_right(self._pos, x) - 1
        p = self._pos[i]
        with memoryview(buf) as mv:
            return zlib.crc32(mv[p - base:x - base], self._val[i])

    def crc(self, buf: bytearray, base: int, a: int, b: int) -> int:
        """CRC-32 of the stream's bytes ``[a, b)`` (``start <= a <= b``; extends the index to ``b``)."""
        self.extend(buf, base, b)
        return range_crc(self.prefix(buf, base, a), self.prefix(buf, base, b), b - a)

    def drop_before(self, buf: bytearray, base: int, x: int) -> None:
        """The caller discards bytes before ``x`` (``start <= x < tip``): keep a checkpoint at ``x``."""
        v = self.prefix(buf, base, x)
        i = bisect_right(self._pos, x)
        self._pos[:i] = [x]
        self._val[:i] = [v]
