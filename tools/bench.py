"""stereocam bench: benchmark figures, not pass/fail (see the command's help for the modes)."""
from __future__ import annotations

import contextlib
import importlib
import time
from typing import Iterator

import click
import numpy as np
from tqdm import tqdm

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


def _stream_fps(url: str, seconds: float, algorithm: int = 0, desc: str = "") -> tuple[float, float, int]:
    import stereocam

    with stereocam.open(url, timeout=3.0) as cam:
        cam.configure(width=640, height=480, fps=60, num_disparities=64, block_size=15,
                      algorithm=algorithm)
        cam.start()
        cam.get_frame(timeout=60.0)  # warm-up (JIT cache load)
        n = 0
        t0 = time.monotonic()
        with tqdm(total=round(seconds * 60), unit="frame", desc=desc, leave=False) as bar:
            while time.monotonic() - t0 < seconds:
                cam.get_frame(timeout=5.0)
                n += 1
                bar.update()
        dt = time.monotonic() - t0
        cam.stop()
        dropped = cam.stats["frames_dropped"]
    return n / dt, n * 640 * 480 * 4 / dt / 1e6, dropped


@contextlib.contextmanager
def _device(kind: str) -> Iterator[str]:
    """A simulator reachable over ``kind``; yields its URL."""
    from stereocam.device_sim import SimulatedCamera
    from stereocam.device_sim.process import ServedSimulator  # the same child-process servers the tests use

    if kind == "sim":
        yield "sim://?seed=1"
    elif kind == "usb":
        import stereocam.device_sim.usb as simusb

        sim = SimulatedCamera(serial="BENCH-USB", seed=1)
        handle = simusb.plug(sim)
        try:
            yield "usb://?serial=BENCH-USB"
        finally:
            handle.unplug()
            sim.close()
    else:
        with ServedSimulator("pty" if kind == "pty" else "tcp:127.0.0.1:0", seed=1) as server:
            yield server.url


ALGORITHMS = {0: "bm", 1: "sgm"}  # values of the device's ``algorithm`` parameter


def bench_transport(seconds: float = 5.0, kinds: tuple[str, ...] = ("sim", "pty", "tcp", "usb")) -> dict[str, float]:
    out = {}
    print(f"end-to-end at 640x480, 64 disparities, all three planes ({seconds:.0f} s each; sim and usb "
          "run the device in this process, pty and tcp in a second one). The camera is asked for 60 fps: "
          "fps is what the whole pipeline (render, rectify, match, link, host) sustains; drops are the "
          "exposures the device skipped, counted and visible as sequence gaps:")
    print(f"  {'transport':<10} {'matcher':<8} {'fps':>6} {'MB/s':>7} {'drops':>6}")
    for kind in kinds:
        for algorithm, label in ALGORITHMS.items():
            with _device(kind) as url:
                fps, mbps, dropped = _stream_fps(url, seconds, algorithm, f"{kind} {label}")
            out[f"{kind}_{label}_fps"] = fps
            print(f"  {kind:<10} {label:<8} {fps:6.1f} {mbps:7.1f} {dropped:6d}")
    return out


MODES = ("protocol", "decoder", "transport", "usb", "matching", "calibration", "calib-real", "all")


@click.command("bench", context_settings={"ignore_unknown_options": True},
               epilog="Exit codes: 0 done (figures, never pass/fail); 1 a camera or simulator failed; 2 bad usage.")
@click.argument("what", type=click.Choice(MODES), default="all")
@click.option("--seconds", type=click.FloatRange(0, min_open=True), default=5.0, show_default=True,
              help="Streaming time per transport (transport mode).")
@click.argument("extra", nargs=-1, type=click.UNPROCESSED)
def command(what: str, seconds: float, extra: tuple[str, ...]) -> int:
    """Print benchmark figures. WHAT is one of:

    \b
    protocol     decoder throughput (MB/s): 640x480 frame messages fed in 64 KiB chunks
    decoder      the decoder's cost per byte on adversarial streams against its clean cost
    transport    end-to-end fps and MB/s at 640x480 over sim, pty, tcp and usb, side by side
    usb          the USB path alone: bulk IN MB/s through pyusb
    matching     the numba matching core against cv2.StereoBM
    calibration  calibration accuracy against the simulator's truth, solver and device tool
    calib-real   the offline tool on real calibration sets against OpenCV's all-pairs solution
    all          protocol, transport, matching and calibration (default)

    Arguments after WHAT that this command does not know go to the usb or matching bench."""
    rest = list(extra)
    if what in ("protocol", "all"):
        bench_protocol()
    if what in ("decoder", "all"):
        importlib.import_module("stereocam.tools.bench_decoder").main([])
    if what in ("transport", "all"):
        bench_transport(seconds)
    if what == "calib-real":
        importlib.import_module("stereocam.tools.bench_calib_real").main(rest)
    if what == "usb":
        importlib.import_module("stereocam.tools.bench_usb").main(rest)
    if what in ("matching", "all"):
        importlib.import_module("stereocam.tools.bench_matching").main(rest)
    if what in ("calibration", "all"):
        importlib.import_module("stereocam.tools.bench_calibration").main([])
        importlib.import_module("stereocam.tools.bench_device_calibration").main([])
    return 0
