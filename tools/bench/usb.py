"""Benchmark the USB path on the simulated bus.

1. raw bulk IN MB/s through pyusb's core (``usb.core.Device.read``) from a streaming stand-in
   firmware, 2. the same through ``stereocam.transports.usb`` (what the SDK uses), 3. frames per
   second of a ``SimulatedCamera`` at 640x480 opened as ``usb://?serial=...``.
"""
from __future__ import annotations

import array
import time
from types import SimpleNamespace
from typing import Any

import click
import usb.core

import stereocam.device_sim.usb as simusb
from stereocam.device_sim.usb.testdevices import SourceDevice
from stereocam.tools.options import CONTEXT, Finite, epilog
from stereocam.transports import usb as usb_transport

MB = 1e6


def bench_pyusb(total: int, chunk: int, read_size: int) -> float:
    """MB/s of bulk IN read with ``usb.core.Device.read`` into a reused buffer."""
    handle = simusb.plug(SourceDevice(serial="BENCH-RAW", chunk=chunk))
    try:
        dev = usb.core.find(backend=simusb.get_backend(),
                            custom_match=lambda d: d.serial_number == "BENCH-RAW")
        buf = array.array("B", bytes(read_size))
        dev.write(simusb.EP_OUT, str(total).encode(), 1000)
        start, got = time.perf_counter(), 0
        while got < total:
            got += dev.read(simusb.EP_IN, buf, 2000)
        return total / (time.perf_counter() - start) / MB
    finally:
        handle.unplug()


def bench_transport(total: int, chunk: int) -> float:
    """MB/s through the SDK's USB transport (Transport.read of up to 1 MiB)."""
    handle = simusb.plug(SourceDevice(serial="BENCH-T", chunk=chunk))
    try:
        with usb_transport.open_transport("usb://?serial=BENCH-T", 2.0) as t:
            t.write(str(total).encode())
            start, got = time.perf_counter(), 0
            while got < total:
                data = t.read(1 << 20, 2.0)
                if not data:
                    raise TimeoutError(f"stream stalled after {got} bytes")
                got += len(data)
            return total / (time.perf_counter() - start) / MB
    finally:
        handle.unplug()


def bench_camera(frames: int, fps: int) -> tuple[float, float]:
    """(frames/s, MB/s of frame data) of a SimulatedCamera at 640x480 over the USB path."""
    import stereocam
    from stereocam.device_sim import SimulatedCamera

    cam = SimulatedCamera(serial="BENCH-CAM", seed=1)
    handle = simusb.plug(cam)
    try:
        with stereocam.open("usb://?serial=BENCH-CAM", timeout=5.0) as camera:
            camera.configure(width=640, height=480, fps=fps)
            camera.start()
            camera.get_frame(timeout=10.0)  # warm-up: JIT compilation, first capture
            start, nbytes = time.perf_counter(), 0
            for _ in range(frames):
                frame = camera.get_frame(timeout=10.0)
                nbytes += sum(a.nbytes for a in (frame.left, frame.right, frame.disparity)
                              if a is not None)
            elapsed = time.perf_counter() - start
            camera.stop()
        return frames / elapsed, nbytes / elapsed / MB
    finally:
        handle.unplug()
        cam.close()


@click.command("usb", context_settings=CONTEXT, epilog=epilog())
@click.option("--mb", type=Finite(min=0, min_open=True), default=256, show_default=True,
              help="MB to stream per raw test.")
@click.option("--chunk", type=click.IntRange(min=1), default=640 * 480 * 2, show_default=True,
              help="Bytes per device IN transfer (one 640x480 16-bit plane).")
@click.option("--read-size", type=click.IntRange(min=512), default=usb_transport.READ_SIZE, show_default=True,
              help="Bytes per host bulk read (a multiple of 512).")
@click.option("--frames", type=click.IntRange(min=1), default=60, show_default=True, help="Frames for the camera test.")
@click.option("--fps", type=click.IntRange(min=1), default=120, show_default=True, help="fps requested from the camera.")
@click.option("--no-camera", is_flag=True, help="Skip the SimulatedCamera test.")
def command(**params: Any) -> int:
    """Benchmark the USB path on the simulated bus."""
    args = SimpleNamespace(**params)
    if args.read_size % simusb.MAX_PACKET_SIZE:
        raise click.BadParameter("must be a multiple of 512", param_hint="--read-size")
    total = int(args.mb * MB)
    print(f"USB bulk IN, {total / MB:.0f} MB, device transfers of {args.chunk} B")
    print(f"  pyusb core, {args.read_size} B reads : {bench_pyusb(total, args.chunk, args.read_size):8.1f} MB/s")
    print(f"  host USB transport            : {bench_transport(total, args.chunk):8.1f} MB/s")
    if not args.no_camera:
        try:
            fps, rate = bench_camera(args.frames, args.fps)
        except ImportError as exc:
            print(f"  camera test skipped: {exc}")
        else:
            print(f"SimulatedCamera 640x480 over usb:// ({args.frames} frames, {args.fps} fps asked)")
            print(f"  {fps:8.1f} frames/s, {rate:8.1f} MB/s of image data")
    return 0

