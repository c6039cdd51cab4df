"""``stereocam recording info|repair|export FILE``: look into, fix and unpack MCAP recordings.

info    duration, frames, topics, drops, the unit and its calibration
repair  rewrite a recording cut short (recorder killed) with its summary and indexes
export  per frame: left/right PNG, disparity .npy (int16, disparity*16) and colour PNG, point cloud .ply
"""
from __future__ import annotations

from stereocam.tools.exit_codes import EXIT_CODES, EXIT_USAGE

import argparse
import json
import sys
from pathlib import Path

from stereocam.recording.reader import Recording
from stereocam.recording.recorder import SUMMARY
from stereocam.recording.repair import repair
from stereocam.tools.camera.capture import save_frame


DROP_KEYS = ("link_lost", "link_incomplete", "host_queue_overflow", "device_dropped", "recorder_dropped")


def describe_file(path: Path) -> dict:
    """What ``recording info`` shows, as plain data."""
    with Recording(path) as rec:
        s, cal = rec.summary_counts, rec.calibration
        repaired = bool(rec.metadata.get(SUMMARY, {}).get("repaired"))
        return {
            "file": str(path), "megabytes": round(path.stat().st_size / 1e6, 3),
            "chunks": len(rec.summary.chunk_indexes), "unit": dict(rec.device), "frames": len(rec),
            "duration_s": round(rec.duration_s, 6),
            "fps": round((len(rec) - 1) / rec.duration_s, 3) if rec.duration_s else None,
            "drops": {k: s[k] for k in DROP_KEYS if k in s}, "repaired": repaired,
            "config": rec.config,
            "calibration": None if cal is None else {
                "source": cal.source, "generation": cal.generation, "id": f"{cal.calibration_id:08x}",
                "image_size": list(cal.calibration.image_size), "fx_px": float(cal.calibration.K_left[0, 0]),
                "baseline_mm": float(cal.calibration.baseline_m * 1000), "lens_model": cal.calibration.lens_model},
            "topics": {ch.topic: {"messages": rec.topics[ch.topic], "schema": _schema_name(rec, ch.schema_id)}
                       for ch in rec.summary.channels.values()},
        }


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
        print(f"calib     {cal['source']} generation {cal['generation']} id {cal['id']}: {w}x{h}, "
              f"fx {cal['fx_px']:.1f}, baseline {cal['baseline_mm']:.1f} mm, {cal['lens_model']}")
    print("topics")
    for topic, t in doc["topics"].items():
        print(f"  {topic:<28} {t['messages']:>7}  {t['schema']}")


def export(path: Path, out: Path, start: int, stop: int | None) -> int:
    n = 0
    with Recording(path) as rec:
        for cap in rec.captures(start, stop):
            save_frame(cap.to_frame(), out, f"frame{cap.index:06d}")
            n += 1
    return n


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="stereocam recording", description=__doc__.splitlines()[0].replace("``", ""),
                                 epilog=EXIT_CODES)
    sub = ap.add_subparsers(dest="what", required=True)
    p = sub.add_parser("info", help="what a recording holds")
    p.add_argument("file", type=Path)
    p.add_argument("--json", action="store_true", help="print one JSON object instead of lines")
    p = sub.add_parser("repair", help="rewrite a recording cut short with its summary and indexes")
    p.add_argument("file", type=Path)
    p.add_argument("--out", type=Path, default=None, help="write here instead of in place")
    p = sub.add_parser("export", help="PNG / NPY / PLY per frame")
    p.add_argument("file", type=Path)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--start", type=int, default=0, help="first frame (from 0)")
    p.add_argument("--stop", type=int, default=None, help="frame to stop before")
    args = ap.parse_args(argv)
    if args.what == "info":
        info(args.file, args.json)
    elif args.what == "repair":
        r = repair(args.file, args.out)
        print(f"{args.out or args.file}: {r.line()}")
    else:
        if args.start < 0 or args.stop is not None and args.stop < 0:
            print("stereocam recording: error: --start and --stop are frame numbers from 0 (not negative), got "
                  f"--start {args.start}" + ("" if args.stop is None else f" --stop {args.stop}"), file=sys.stderr)
            return EXIT_USAGE
        n = export(args.file, args.out, args.start, args.stop)
        print(f"{n} frames exported to {args.out}")
    return 0
