"""stereocam bench: benchmark figures, not pass/fail; one subcommand per benchmark (see MODULES)."""
from __future__ import annotations

import importlib
import time

import click
import numpy as np

from stereocam.protocol import messages as m
from stereocam.protocol.framing import Decoder
from stereocam.tools.options import CONTEXT, Finite, epilog


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


MODULES: dict[str, tuple[str, str]] = {
    "decoder": ("decoder", "the decoder's cost per byte on adversarial streams against its clean cost"),
    "transport": ("transport", "end-to-end fps, MB/s, drops, latency p50/p99 at 640x480 over sim, pty, tcp, usb"),
    "usb": ("usb", "the USB path alone: bulk IN MB/s through pyusb"),
    "matching": ("matching", "the numba matching core against cv2.StereoBM (--algorithm sgm: against SGBM)"),
    "calibration": ("calibration", "calibration accuracy of the solver against the simulator's truth"),
    "device-calibration": ("device_calibration", "device-mode calibration against truth, depth through it"),
    "calib-synthetic": ("calib_synthetic", "the calibration tool on synthetic views through every lens model and "
                                           "board class, against the truth"),
    "calib-real": ("calib_real", "the offline tool on real calibration sets against OpenCV's all-pairs solution"),
    "sync": ("sync", "three heads on one trigger line: skew within matched sets, clock-map error vs truth"),
    "firmware": ("firmware", "a 2 MiB signed image installed per transport, and one update's state trace"),
    "record": ("record", "the recorder's ceiling (MB/s), a live recording's drops, seek time by frame index"),
    "rematch": ("rematch", "stereocam rematch frames/s with 1 and 2 local Dask workers"),
    "post": ("post", "the post-processing chain at 640x480 per stage; --quality: density and bad-2.0 vs SGBM"),
}
"""name -> (module in stereocam.tools.bench, one-line help); each module provides ``command``."""

EPILOG = epilog("Figures, never pass/fail: 0 done; a bench with targets (calibration, device-calibration, "
                "calib-synthetic, calib-real) exits 1 when it misses them.")


class BenchTable(click.Group):
    """``protocol`` and ``all`` here, the other benches from MODULES, imported only when run."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return ["protocol", *MODULES, "all"]

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name in MODULES:
            return importlib.import_module(f"stereocam.tools.bench.{MODULES[name][0]}").command
        return super().get_command(ctx, name)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        with formatter.section("Benchmarks"):
            formatter.write_dl([("protocol", "decoder throughput (MB/s): 640x480 frame messages in 64 KiB reads"),
                                *((name, text) for name, (_, text) in MODULES.items()),
                                ("all", "protocol, decoder, transport, matching, calibration, device-calibration "
                                        "(the default)")])


@click.group("bench", cls=BenchTable, invoke_without_command=True, context_settings=CONTEXT, epilog=EPILOG,
             subcommand_metavar="[BENCHMARK [OPTIONS]]")
@click.pass_context
def command(ctx: click.Context) -> int | None:
    """Print benchmark figures; without a BENCHMARK, all of the quick ones. Each benchmark's --help
    lists its options and their defaults."""
    if ctx.invoked_subcommand is None:
        return ctx.invoke(run_all)
    return None


@command.command("protocol", epilog=EPILOG)
@click.option("--seconds", type=Finite(0, min_open=True), default=2.0, show_default=True,
              help="Decoding time.")
def protocol(seconds: float) -> int:
    """Decoder throughput (MB/s): 640x480 frame messages fed in 64 KiB chunks."""
    bench_protocol(seconds)
    return 0


@command.command("all", epilog=EPILOG)
@click.option("--seconds", type=Finite(0, min_open=True), default=5.0, show_default=True,
              help="Capture time per transport.")
@click.pass_context
def run_all(ctx: click.Context, seconds: float) -> int:
    """protocol, decoder, transport, matching, calibration and device-calibration with their defaults."""
    bench_protocol()
    group = ctx.parent.command if ctx.parent is not None else command
    assert isinstance(group, click.Group)
    for name, extra in (("decoder", {}), ("transport", {"seconds": seconds}), ("matching", {}),
                        ("calibration", {}), ("device-calibration", {})):
        sub = group.get_command(ctx, name)
        assert sub is not None, name
        ctx.invoke(sub, **extra)
    return 0
