"""``stereocam recording info|repair|export FILE``: look into, fix and unpack MCAP recordings.

info    duration, frames, topics, drops, the unit and its calibration
repair  rewrite a recording cut short (recorder killed) with its summary and indexes
export  per frame: left/right PNG, disparity .npy (int16, disparity*16) and colour PNG, point cloud .ply
"""
from __future__ import annotations

import json
from pathlib import Path

import click

from stereocam.calibration_io import id_text
from stereocam.recording.reader import Recording
from stereocam.recording.recorder import SUMMARY, RecordingError
from stereocam.recording.repair import repair
from stereocam.tools.camera.capture import save_frame
from stereocam.tools.options import CONTEXT, INPUT_FILE, epilog


DROP_KEYS = ("link_lost", "link_incomplete", "host_queue_overflow", "device_dropped", "recorder_dropped")


def describe_file(path: Path) -> dict:
    """What ``recording info`` shows, as plain data."""
    with Recording(path) as rec:
        s, cal = rec.summary_counts, rec.calibration
        repaired = bool(rec.metadata.get(SUMMARY, {}).get("repaired"))
        return {
            "file": str(path), "megabytes": round(path.stat().st_size / 1e6, 3),
            "chunks": len(rec.summary.chunk_indexes), "unit": _typed(rec.device), "frames": len(rec),
            "duration_s": round(rec.duration_s, 6),
            "fps": round((len(rec) - 1) / rec.duration_s, 3) if rec.duration_s else None,
            "drops": {k: s[k] for k in DROP_KEYS if k in s}, "repaired": repaired,
            "config": rec.config,
            "calibration": None if cal is None else {
                "source": cal.source, "generation": cal.generation, "id": cal.calibration_id,
                "image_size": list(cal.calibration.image_size), "fx_px": float(cal.calibration.K_left[0, 0]),
                "baseline_mm": float(cal.calibration.baseline_m * 1000), "lens_model": cal.calibration.lens_model},
            "topics": {ch.topic: {"messages": rec.topics[ch.topic], "schema": _schema_name(rec, ch.schema_id)}
                       for ch in rec.summary.channels.values()},
        }


def _typed(unit: dict[str, str]) -> dict[str, str | int]:
    """The recorded INFO (MCAP metadata holds strings) with its numbers as numbers."""
    return {k: int(v) if v.isascii() and v.lstrip("-").isdigit() else v for k, v in unit.items()}


def _schema_name(rec: Recording, schema_id: int) -> str:
    schema = rec.summary.schemas.get(schema_id)
    return schema.name if schema is not None else f"(no schema {schema_id})"


def info(path: Path, as_json: bool = False) -> None:
    doc = describe_file(path)
    if as_json:
        print(json.dumps(doc, indent=2))
        return
    d, cfg, cal = doc["unit"], doc["config"], doc["calibration"]
    print(f"file      {path} ({doc['megabytes']:.1f} MB, {doc['chunks']} chunks)")
    print(f"unit      {d.get('model')} serial {d.get('serial')} firmware {d.get('firmware_version')} "
          f"protocol {d.get('protocol_version')}")
    print(f"frames    {doc['frames']} over {doc['duration_s']:.2f} s" + (f" ({doc['fps']:.1f} fps)" if doc["fps"] else ""))
    print("drops     " + ", ".join(f"{k} {v}" for k, v in doc["drops"].items())
          + (" (repaired file)" if doc["repaired"] else ""))
    print(f"config    {cfg.get('width')}x{cfg.get('height')} @ {cfg.get('fps')} fps, outputs {cfg.get('outputs')}, "
          f"{cfg.get('num_disparities')} disparities, block {cfg.get('block_size')}")
    if cal is None:
        print("calib     none stored (raw frames)")
    else:
        w, h = cal["image_size"]
        print(f"calib     {cal['source']} generation {cal['generation']} id {id_text(cal['id'])}: {w}x{h}, "
              f"fx {cal['fx_px']:.1f}, baseline {cal['baseline_mm']:.1f} mm, {cal['lens_model']}")
    print("topics")
    for topic, t in doc["topics"].items():
        print(f"  {topic:<28} {t['messages']:>7}  {t['schema']}")


def export(path: Path, out: Path, start: int, stop: int | None) -> int:
    """Frames ``start`` .. ``stop - 1`` of ``path`` saved into ``out``; their number. A range that
    selects no frame of the recording is a RecordingError naming the frames and seconds it has."""
    n = 0
    with Recording(path) as rec:
        if start >= (len(rec) if stop is None else min(stop, len(rec))):
            has = f"frames 0..{len(rec) - 1} ({rec.duration_s:.2f} s)" if len(rec) else "no frame"
            raise RecordingError(f"--start {start}" + ("" if stop is None else f" --stop {stop}")
                                 + f" selects no frame of {path}, which has {has}")
        for cap in rec.captures(start, stop):
            save_frame(cap.to_frame(), out, f"frame{cap.index:06d}")
            n += 1
    return n


@click.group("recording", epilog=epilog(), context_settings=CONTEXT)
def command() -> None:
    """Look into, fix and unpack MCAP recordings."""




@command.command("info", epilog=epilog())
@click.argument("file", type=INPUT_FILE)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of lines.")
def info_command(file: Path, as_json: bool) -> int:
    """Duration, frames, topics, drops, the unit and its calibration."""
    info(file, as_json)
    return 0


@command.command("repair", epilog=epilog())
@click.argument("file", type=INPUT_FILE)
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write here.  [default: FILE, in place]")
def repair_command(file: Path, out: Path | None) -> int:
    """Rewrite a recording cut short (recorder killed) with its summary and indexes."""
    r = repair(file, out)
    click.echo(f"{out or file}: {r.line()}")
    return 0


@command.command("export", epilog=epilog())
@click.argument("file", type=INPUT_FILE)
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), required=True, help="Folder to write to.")
@click.option("--start", type=int, default=0, show_default=True, help="First frame (from 0).")
@click.option("--stop", type=int, default=None, help="Frame to stop before.  [default: the end]")
def export_command(file: Path, out: Path, start: int, stop: int | None) -> int:
    """Per frame: left/right PNG, disparity .npy (int16, disparity*16) and colour PNG, point cloud .ply."""
    if start < 0 or stop is not None and stop < 0:
        raise click.UsageError(f"--start and --stop are frame numbers from 0 (not negative), got --start {start}"
                               + ("" if stop is None else f" --stop {stop}"))
    if stop is not None and stop <= start:
        raise click.UsageError(f"--stop is the frame to stop before: it must be after --start, got --start {start} "
                               f"--stop {stop}")
    n = export(file, out, start, stop)
    click.echo(f"{n} frames exported to {out}")
    return 0
