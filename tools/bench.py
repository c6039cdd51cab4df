"""``stereocam bench [protocol|transport|matching|all]``: figures, not pass/fail.

protocol  — decoder throughput (MB/s) on a stream of 640x480 frame messages fed in 64 KiB chunks.
transport — end-to-end frames/s and MB/s at 640x480 (left, right, disparity) per transport, the
            simulator rendering and matching every frame; side by side in one run.
matching  — the numba matching core against cv2.StereoBM (tools/bench_matching.py).
"""
from __future__ import annotations

import argparse
import importlib
import time

import numpy as np

from protocol import messages as m
from protocol.framing import Decoder


def bench_protocol(seconds: float = 2.0) -> dict[str, float]:
    rng = np.random.default_rng(0)
    plane = rng.integers(0, 255, 640 * 480 * 4, dtype=np.uint8).tobytes()  # one capture's bytes
    chunk = 128 * 1024
    stream = b"".join(m.encode(m.FrameData(1, 1, off, plane[off:off + chunk])) for off in range(0, len(plane), chunk))
    pieces = [stream[i:i + 65536] for i in range(0, len(stream), 65536)]
    dec = Decoder()
    n = 0
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        for p in pieces:
            for pkt in dec.feed(p):
                m.decode_packet(pkt)
        n += 1
    dt = time.perf_counter() - t0
    assert dec.stats.dropped == 0
    mbps = n * len(stream) / dt / 1e6
    print(f"protocol decode: {mbps:.0f} MB/s ({dec.stats.packets / dt:.0f} packets/s, 128 KiB payloads, "
          f"64 KiB reads, CRC-checked and typed)")
    return {"decode_MBps": mbps}


def _stream_fps(url: str, seconds: float) -> tuple[float, float, int]:
    import host

    with host.open(url, timeout=3.0) as cam:
        cam.configure(width=640, height=480, fps=60, num_disparities=64, block_size=15)
        cam.start()
        cam.get_frame(timeout=60.0)  # warm-up (JIT cache load)
        n = 0
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds:
            cam.get_frame(timeout=5.0)
            n += 1
        dt = time.monotonic() - t0
        cam.stop()
        dropped = cam.stats["frames_dropped"]
    return n / dt, n * 640 * 480 * 4 / dt / 1e6, dropped


def bench_transport(seconds: float = 5.0, kinds: tuple[str, ...] = ("sim", "pty", "tcp")) -> dict[str, float]:
    from device_sim.process import ServedSimulator  # the same child-process servers the tests use

    out = {}
    print(f"end-to-end at 640x480, 64 disparities, all three planes ({seconds:.0f} s each):")
    print(f"  {'transport':<10} {'fps':>6} {'MB/s':>7} {'device drops':>13}")
    for kind in kinds:
        server = None if kind == "sim" else ServedSimulator("pty" if kind == "pty" else "tcp:127.0.0.1:0")
        try:
            fps, mbps, dropped = _stream_fps("sim://?seed=1" if server is None else server.url, seconds)
        finally:
            if server is not None:
                server.stop()
        out[f"{kind}_fps"] = fps
        print(f"  {kind:<10} {fps:6.1f} {mbps:7.1f} {dropped:13d}")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="stereocam bench", description=__doc__.splitlines()[0])
    ap.add_argument("what", nargs="?", default="all", choices=["protocol", "transport", "matching", "all"])
    ap.add_argument("--seconds", type=float, default=5.0)
    args, rest = ap.parse_known_args(argv)
    if args.what in ("protocol", "all"):
        bench_protocol()
    if args.what in ("transport", "all"):
        bench_transport(args.seconds)
    if args.what in ("matching", "all"):
        importlib.import_module("tools.bench_matching").main(rest)
    return 0
