"""``stereocam bench firmware``: a 2 MiB signed image installed per transport (in-process, TCP,
USB) side by side, and the states a unit goes through in one update (a trace)."""
from __future__ import annotations

import contextlib
import hashlib
import time
from types import SimpleNamespace
from typing import Any, Iterator

import click

import stereocam
from stereocam import firmware_update as fw
from stereocam.device_sim import SimulatedCamera
from stereocam.device_sim.boot.factory import DEV_SIGNING_KEY
from stereocam.device_sim.handlers.device_info import FACTORY_BUILD, MODEL
from stereocam.device_sim.process import ServedSimulator
from stereocam.protocol import messages as m
from stereocam.protocol.firmware_image import FirmwareBuild, build_image
from stereocam.tools.options import CONTEXT, epilog


def signed_image(version: str, size: int) -> bytes:
    build = FirmwareBuild(version, FACTORY_BUILD.protocol_minor, FACTORY_BUILD.capabilities,
                          FACTORY_BUILD.parameter_defaults)
    bare = len(build_image(build, DEV_SIGNING_KEY, target=MODEL))
    return build_image(build, DEV_SIGNING_KEY, target=MODEL, code=bytes(i * 31 & 0xFF for i in range(size - bare)))


@contextlib.contextmanager
def _unit(kind: str, serial: str) -> Iterator[str]:
    if kind == "tcp":
        with ServedSimulator("tcp:127.0.0.1:0") as served:
            yield served.url
        return
    sim = SimulatedCamera(serial=serial, seed=9)
    if kind == "usb":
        import stereocam.device_sim.usb as simusb

        handle = simusb.plug(sim)
        yield f"usb://?serial={serial}"
        handle.unplug()
    else:
        yield f"sim://?serial={serial}"
    sim.close()


def _states(cam) -> str:
    st = cam.firmware_status()
    slots = " ".join(f"{s.slot}={s.version or '-'}:{s.state.name}" for s in st.slots)
    transfer = f" transfer {st.transfer[0]}/{st.transfer[1]}" if st.transfer[1] else ""
    return f"running {st.running} ({st.mode.name}) {slots}{transfer}"


def trace(image: bytes) -> list[str]:
    """One update in-process, step by step, with the unit's state after each step."""
    sim = SimulatedCamera(serial="TRACE", seed=9)
    lines = []
    with stereocam.open("sim://?serial=TRACE", timeout=2.0) as cam:
        lines.append(f"factory:            {_states(cam)}")
        half = len(image) // 2
        cam.request(m.UpdateBegin(len(image), hashlib.sha256(image).digest()))
        for off in range(0, half, m.MAX_UPDATE_CHUNK):
            cam.request(m.UpdateData(off, image[off:min(off + m.MAX_UPDATE_CHUNK, half)]))
        lines.append(f"transfer (half):    {_states(cam)}")
        fw.transfer(cam.request, image)
        lines.append(f"transfer + verify:  {_states(cam)}")
        cam.request(m.UpdateActivate())
        fw.await_reboot(cam, 30.0)
        lines.append(f"activate + reboot:  {_states(cam)}   boot: {'; '.join(sim.booted.trace)}")
        cam.request(m.UpdateConfirm())
        lines.append(f"confirm:            {_states(cam)}")
    sim.reboot()
    lines.append(f"next boot:          boot: {'; '.join(sim.booted.trace)}")
    sim.close()
    return lines


@click.command("firmware", context_settings=CONTEXT, epilog=epilog())
@click.option("--size", type=click.IntRange(min=1), default=2 << 20, show_default=True, help="Image size in bytes.")
@click.option("--repeat", type=click.IntRange(min=1), default=2, show_default=True, help="Updates per transport (the best counts).")
def command(**params: Any) -> int:
    """A signed image installed per transport (in-process, TCP, USB), and one update's state trace."""
    args = SimpleNamespace(**params)
    image = signed_image("1.2.0", args.size)
    print(f"firmware update of a {len(image)}-byte signed image (transfer, verify, reboot, reconnect, read-back, "
          "confirm)")
    print(f"  {'transport':<10} {'seconds':>8} {'MB/s':>6}   (best of {args.repeat})")
    for kind in ("sim", "tcp", "usb"):
        best = float("inf")
        for i in range(args.repeat):
            with _unit(kind, f"BENCH-{kind}-{i}") as url, stereocam.open(url, timeout=2.0) as cam:
                t0 = time.perf_counter()
                cam.update_firmware(image)
                best = min(best, time.perf_counter() - t0)
        print(f"  {kind:<10} {best:8.2f} {len(image) / best / 1e6:6.2f}")
    print("states of one update (in-process):")
    for line in trace(image):
        print("  " + line)
    return 0
