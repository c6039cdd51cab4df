"""``stereocam bench decoder``: the decoder's cost per input byte on clean and adversarial streams.

Every stream is fed in 64 KiB reads to a fresh Decoder; the figure is wall time per input byte and
its ratio to the clean cost (a stream of 640x480 capture messages). SPEC §3.1 states the bound
these shapes probe; tests/protocol/test_decoder_hostile.py checks it with a generous margin.
"""
from __future__ import annotations

import binascii
import struct
import time
from types import SimpleNamespace
from typing import Any, Callable

import click
import numpy as np

from stereocam.protocol import messages as m
from stereocam.protocol.framing import MAGIC, MAX_PAYLOAD, Decoder
from stereocam.tools.options import CONTEXT, Finite, epilog

READ = 65536


def valid_header(payload_len: int, msg_type: int = m.MsgType.FRAME_DATA) -> bytes:
    """A header whose CRC checks out, announcing ``payload_len`` bytes that never come."""
    head = struct.pack("<4sBBBBHHIH", MAGIC, 1, 1, 20, 0, msg_type, 0, payload_len, 0)
    return head + binascii.crc_hqx(head, 0xFFFF).to_bytes(2, "little")


def clean_frames(size: int) -> bytes:
    """One 640x480 capture (left, right, disparity) as 128 KiB FRAME_DATA messages."""
    plane = np.random.default_rng(0).integers(0, 255, 640 * 480 * 4, dtype=np.uint8).tobytes()
    one = b"".join(m.encode(m.FrameData(1, 1, o, plane[o:o + 131072])) for o in range(0, len(plane), 131072))
    return (one * (size // len(one) + 1))[:size]


def clean_small(size: int) -> bytes:
    one = m.encode(m.Status(123456, True, 0, {"frames_captured": 5, "rx_bytes": 77}), 9)
    return one * (size // len(one))


def big_headers(size: int, filler: int = 16, payload_len: int = MAX_PAYLOAD) -> bytes:
    """The issue's shape: CRC-valid headers announcing 1 MiB, each followed by ``filler`` bytes."""
    unit = valid_header(payload_len) + b"\x55" * filler
    return unit * (size // len(unit))


def random_length_headers(size: int) -> bytes:
    rng = np.random.default_rng(1)
    parts, n = [], 0
    while n < size:
        part = valid_header(int(rng.integers(0, MAX_PAYLOAD + 1))) + rng.bytes(int(rng.integers(0, 40)))
        parts.append(part)
        n += len(part)
    return b"".join(parts)


def magic_dense(size: int) -> bytes:
    return MAGIC * (size // 4)


def random_bytes(size: int) -> bytes:
    return np.random.default_rng(2).bytes(size)


def flipped_frames(size: int) -> bytes:
    """Clean captures with one bit flipped every 1000 bytes."""
    b = np.frombuffer(clean_frames(size), dtype=np.uint8).copy()
    b[::1000] ^= 0x10
    return b.tobytes()


SHAPES: dict[str, Callable[[int], bytes]] = {
    "clean 640x480 captures": clean_frames, "clean STATUS replies": clean_small,
    "random bytes": random_bytes, "magic every 4 bytes": magic_dense,
    "1 MiB headers + 16 B filler": big_headers, "1 MiB headers back to back": lambda n: big_headers(n, 0),
    "random-length headers": random_length_headers, "captures, 1 flip per 1000 B": flipped_frames,
}


def cost_per_byte(stream: bytes, repeat: int = 1) -> float:
    """Best-of-``repeat`` seconds per input byte for a fresh decoder fed in 64 KiB reads."""
    best = float("inf")
    for _ in range(repeat):
        dec = Decoder()
        t0 = time.perf_counter()
        for i in range(0, len(stream), READ):
            dec.feed(stream[i:i + READ])
        best = min(best, (time.perf_counter() - t0) / len(stream))
    return best


@click.command("decoder", context_settings=CONTEXT, epilog=epilog())
@click.option("--mib", type=Finite(min=0, min_open=True), default=4.0, show_default=True,
              help="Stream size per shape, MiB.")
def command(**params: Any) -> int:
    """The decoder's cost per input byte on clean and adversarial streams."""
    args = SimpleNamespace(**params)
    size = int(args.mib * (1 << 20))
    costs = {name: cost_per_byte(make(size), 3) for name, make in SHAPES.items()}
    clean = costs["clean 640x480 captures"]
    print(f"decoder cost per input byte, {args.mib:g} MiB per shape, 64 KiB reads, best of 3:")
    print(f"  {'stream':<30} {'ns/byte':>9} {'x clean':>8}")
    for name, c in costs.items():
        print(f"  {name:<30} {c * 1e9:9.2f} {c / clean:8.1f}")
    worst = max(costs, key=lambda n: costs[n])
    print(f"worst: {worst}, {costs[worst] / clean:.0f}x the clean cost per byte")
    return 0
