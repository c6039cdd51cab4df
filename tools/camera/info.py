"""stereocam info URL: identity, calibration, configuration and counters of one camera."""
from __future__ import annotations

import json
from typing import Any

import click

import stereocam
from stereocam.calibration_io import id_text
from stereocam.protocol.messages import Capability
from stereocam.protocol.params import VALUE_NAMES, Output
from stereocam.tools.options import CONTEXT, Finite, epilog


def value_name(name: str, value: int) -> str | int:
    """Enumerated parameters by name (trigger_mode software, outputs left+right, algorithm sgm);
    others as numbers."""
    if value in VALUE_NAMES.get(name, {}):
        return VALUE_NAMES[name][value]
    if name == "outputs":
        return "+".join(str(p.name).lower() for p in Output if value & p) or "none"
    return value


def read_info(cam: stereocam.Camera) -> dict[str, Any]:
    """Everything ``info`` prints, as plain data."""
    i = cam.info()
    stored = cam.read_calibration() if i.capabilities & Capability.CALIBRATION else None
    st = cam.status()
    return {
        "model": i.model, "serial": i.serial, "firmware": i.firmware_version,
        "protocol": f"{i.protocol_version[0]}.{i.protocol_version[1]}",
        "sensor": f"{i.sensor_width}x{i.sensor_height}", "max_payload": i.max_payload,
        "calibration": None if stored is None else {"id": stored.calibration_id, "source": stored.source,
                                                    "generation": stored.generation},
        "config": {name: value_name(name, v) for name, v in cam.config().items()},
        "uptime_s": round(st.uptime_us / 1e6, 1), "streaming": st.streaming, "counters": dict(st.counters),
    }


def format_text(doc: dict[str, Any]) -> str:
    lines = [f"{k} {doc[k]}" for k in ("model", "serial", "firmware", "protocol", "sensor", "max_payload")]
    cal = doc["calibration"]
    lines.append("calibration none (uncalibrated: raw images, no disparity)" if cal is None else
                 f"calibration id {id_text(cal['id'])} source {cal['source']} generation {cal['generation']}")
    lines += [f"config.{k} {v}" for k, v in doc["config"].items()]
    lines += [f"uptime_s {doc['uptime_s']}", f"streaming {doc['streaming']}"]
    lines += [f"counter.{k} {v}" for k, v in doc["counters"].items()]
    return "\n".join(lines)


@click.command("info", epilog=epilog(), context_settings=CONTEXT)
@click.argument("url")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of lines.")
@click.option("--timeout", type=Finite(0, min_open=True), default=2.0, show_default=True,
              help="Seconds to wait for each reply.")
def command(url: str, as_json: bool, timeout: float) -> int:
    """Print a camera's identity, calibration (id, source, generation), configuration (enumerations
    by name) and device counters. URL: as stereocam list prints it (sim://?seed=N, usb://?serial=SN,
    socket://HOST:PORT, a device path)."""
    with stereocam.open(url, timeout=timeout) as cam:
        doc = read_info(cam)
    click.echo(json.dumps(doc, indent=2) if as_json else format_text(doc))
    return 0
