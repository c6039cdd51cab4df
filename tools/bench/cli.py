"""stereocam bench: benchmark figures, not pass/fail (see the command's help for the modes)."""
from __future__ import annotations

import importlib
import time

import click
import numpy as np

from stereocam.protocol import messages as m
from stereocam.protocol.framing import Decoder


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


MODES = ("protocol", "decoder", "transport", "usb", "matching", "calibration", "calib-real", "sync", "firmware",
         "record", "rematch",
         "all")


@click.command("bench", context_settings={"ignore_unknown_options": True},
               epilog="Exit codes: 0 done (figures, never pass/fail); 1 a camera or simulator failed; 2 bad usage.")
@click.argument("what", type=click.Choice(MODES), default="all")
@click.option("--seconds", type=click.FloatRange(0, min_open=True), default=None,
              help="Capture time per transport (transport: 5 s, record: 5 s, sync: 120 s when not given).")
@click.argument("extra", nargs=-1, type=click.UNPROCESSED)
def command(what: str, seconds: float | None, extra: tuple[str, ...]) -> int:
    """Print benchmark figures. WHAT is one of:

    \b
    protocol     decoder throughput (MB/s): 640x480 frame messages fed in 64 KiB chunks
    decoder      the decoder's cost per byte on adversarial streams against its clean cost
    transport    end-to-end fps, MB/s, drops, latency p50/p99 at 640x480 over sim, pty, tcp,
                 usb high and super speed (--algorithm bm|sgm, --transport KIND), stage profile
    usb          the USB path alone: bulk IN MB/s through pyusb
    matching     the numba matching core against cv2.StereoBM
    calibration  calibration accuracy against the simulator's truth, solver and device tool
    calib-real   the offline tool on real calibration sets against OpenCV's all-pairs solution
    sync         three heads on one trigger line: skew within matched sets, clock-map error vs truth
    firmware     a 2 MiB signed image installed per transport, and one update's state trace
    record       the recorder's ceiling (MB/s), a live recording's drops, seek time by frame index
    rematch      stereocam rematch frames/s with 1 and 2 local Dask workers
    all          protocol, decoder, transport, matching and calibration (default)

    Arguments after WHAT that this command does not know go to the transport, usb or matching bench."""
    rest = list(extra)
    timed = rest + ([] if seconds is None else ["--seconds", str(seconds)])  # for the modes with a --seconds
    if what in ("protocol", "all"):
        bench_protocol()
    if what in ("decoder", "all"):
        importlib.import_module("stereocam.tools.bench.decoder").main([])
    if what in ("transport", "all"):
        importlib.import_module("stereocam.tools.bench.transport").main(rest if what == "transport" else [],
                                                                        5.0 if seconds is None else seconds)
    if what == "sync":  # minutes of capture: only when asked for
        importlib.import_module("stereocam.tools.bench.sync").main(timed)
    if what == "firmware":
        importlib.import_module("stereocam.tools.bench.firmware").main(rest)
    if what == "calib-real":
        importlib.import_module("stereocam.tools.bench.calib_real").main(rest)
    if what == "record":
        importlib.import_module("stereocam.tools.bench.record").main(timed)
    if what == "rematch":
        importlib.import_module("stereocam.tools.bench.rematch").main(rest)
    if what == "usb":
        importlib.import_module("stereocam.tools.bench.usb").main(rest)
    if what in ("matching", "all"):
        importlib.import_module("stereocam.tools.bench.matching").main(rest)
    if what in ("calibration", "all"):
        importlib.import_module("stereocam.tools.bench.calibration").main([])
        importlib.import_module("stereocam.tools.bench.device_calibration").main([])
    return 0
