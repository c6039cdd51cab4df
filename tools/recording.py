"""``stereocam recording info|repair|export FILE``: look into, fix and unpack MCAP recordings.

info    duration, frames, topics, drops, the unit and its calibration
repair  rewrite a recording cut short (recorder killed) with its summary and indexes
export  per frame: left/right PNG, disparity .npy (int16, disparity*16) and colour PNG, point cloud .ply
"""
from __future__ import annotations

import argparse
from pathlib import Path

from stereocam.recording.reader import Recording
from stereocam.recording.repair import repair
from stereocam.tools.capture import save_frame


def info(path: Path) -> None:
    with Recording(path) as rec:
        d, s = rec.device, rec.metadata.get("stereocam.summary", {})
        print(f"file      {path} ({path.stat().st_size / 1e6:.1f} MB, {len(rec.summary.chunk_indexes)} chunks)")
        print(f"unit      {d.get('model')} serial {d.get('serial')} firmware {d.get('firmware_version')} "
              f"protocol {d.get('protocol_version')}")
        print(f"frames    {len(rec)} over {rec.duration_s:.2f} s"
              + (f" ({(len(rec) - 1) / rec.duration_s:.1f} fps)" if rec.duration_s else ""))
        print("drops     " + ", ".join(f"{k} {s[k]}" for k in ("link_lost", "link_incomplete", "host_queue_overflow",
                                                                 "device_dropped", "recorder_dropped") if k in s)
              + (" (repaired file)" if s.get("repaired") else ""))
        cfg = rec.config
        print(f"config    {cfg.get('width')}x{cfg.get('height')} @ {cfg.get('fps')} fps, outputs {cfg.get('outputs')}, "
              f"{cfg.get('num_disparities')} disparities, block {cfg.get('block_size')}")
        cal = rec.calibration
        if cal is None:
            print("calib     none stored (raw frames)")
        else:
            c = cal.calibration
            print(f"calib     {cal.source} generation {cal.generation} id {cal.calibration_id:08x}: "
                  f"{c.image_size[0]}x{c.image_size[1]}, fx {c.K_left[0, 0]:.1f}, baseline {abs(c.T[0]) * 1000:.1f} mm")
        print("topics")
        for ch in rec.summary.channels.values():
            schema = rec.summary.schemas[ch.schema_id].name
            print(f"  {ch.topic:<28} {rec.topics[ch.topic]:>7}  {schema}")


def export(path: Path, out: Path, start: int, stop: int | None) -> int:
    n = 0
    with Recording(path) as rec:
        for cap in rec.captures(start, stop):
            save_frame(cap.to_frame(), out, f"frame{cap.index:06d}")
            n += 1
    return n


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="stereocam recording", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="what", required=True)
    sub.add_parser("info", help="what a recording holds").add_argument("file", type=Path)
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
        info(args.file)
    elif args.what == "repair":
        r = repair(args.file, args.out)
        state = "was complete" if r.was_complete else "was cut short"
        print(f"{args.out or args.file}: {r.frames} frames kept ({state}; a trailing partial capture dropped: "
              f"{r.dropped_partial}); {r.bytes_before} -> {r.bytes_after} bytes")
    else:
        n = export(args.file, args.out, args.start, args.stop)
        print(f"{n} frames exported to {args.out}")
    return 0
