"""``stereocam calibration export URL --size WxH [--out DIR]``: ROS camera_info of what a unit stores.

Reads the calibration in force (or --source factory|user) from the camera and writes
left_WxH.yaml / right_WxH.yaml for streams of that size (tools/calibration/camera_info.py), plus
calibration.json of the stored record. Without --size: every size the unit offers.
"""
from __future__ import annotations

import json
from pathlib import Path

import click

import stereocam
from stereocam.tools.calibration.camera_info import stream_sizes, write_camera_info
from stereocam.tools.exit_codes import EXIT_NO_CALIBRATION
from stereocam.tools.options import CONTEXT, SIZE, epilog



@click.group("calibration", epilog=epilog(), context_settings=CONTEXT)
def command() -> None:
    """The calibration a unit stores, as files other software reads."""


@command.command("export", epilog=epilog("Exit codes: 3 the unit holds no calibration of that --source."))
@click.argument("url")
@click.option("--size", "sizes", type=SIZE, multiple=True,
              help="Stream size (repeatable).  [default: every size the unit offers]")
@click.option("--source", type=click.Choice(["active", "factory", "user"]), default="active", show_default=True,
              help="Record to read.")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("."), show_default=True,
              help="Output folder.")
def export(url: str, sizes: tuple[tuple[int, int], ...], source: str, out: Path) -> int:
    """Write ROS camera_info files (left_WxH.yaml, right_WxH.yaml) and calibration.json from the
    calibration stored on a unit."""
    with stereocam.open(url, timeout=2.0) as cam:
        stored = cam.read_calibration(source)
        info = cam.info()
    if stored is None:
        click.echo(f"stereocam calibration: error: {info.serial} holds no {source} calibration", err=True)
        return EXIT_NO_CALIBRATION
    out.mkdir(parents=True, exist_ok=True)
    doc = stored.calibration.to_json_dict()
    doc.update(source=stored.source, generation=stored.generation, calibration_id=stored.calibration_id,
               serial=info.serial)
    (out / "calibration.json").write_text(json.dumps(doc, indent=2) + "\n")
    for size in sizes or stream_sizes((info.sensor_width, info.sensor_height)):
        paths = write_camera_info(stored.calibration, out, size)
        click.echo("wrote " + ", ".join(str(p) for p in paths))
    return 0
