"""``stereocam calibration export URL --size WxH [--out DIR]``: ROS camera_info of what a unit stores.

Reads the calibration in force (or --source factory|user) from the camera and writes
left_WxH.yaml / right_WxH.yaml for streams of that size (tools/calibration/camera_info.py), plus
calibration.json of the stored record. Without --size: every size the unit offers.
"""
from __future__ import annotations

from stereocam.tools.exit_codes import EXIT_CODES

import argparse
import json
import sys
from pathlib import Path

import stereocam
from stereocam.tools.calibration.camera_info import stream_sizes, write_camera_info


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WxH, e.g. 640x480, got {text!r}") from None
    return w, h


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="stereocam calibration", description=__doc__.splitlines()[0].replace("``", ""),
                                 epilog=EXIT_CODES,
                                 formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    ex = sub.add_parser("export", help="write ROS camera_info files from the calibration stored on a unit")
    ex.add_argument("url", help="camera URL")
    ex.add_argument("--size", type=_size, action="append", metavar="WxH",
                    help="stream size (repeatable; default every size the unit offers)")
    ex.add_argument("--source", choices=["active", "factory", "user"], default="active", help="record to read")
    ex.add_argument("--out", type=Path, default=Path("."), help="output folder")
    args = ap.parse_args(argv)
    with stereocam.open(args.url, timeout=2.0) as cam:
        stored = cam.read_calibration(args.source)
        info = cam.info()
    if stored is None:
        print(f"stereocam calibration: error: {info.serial} holds no {args.source} calibration", file=sys.stderr)
        return 3
    sizes = args.size or stream_sizes((info.sensor_width, info.sensor_height))
    args.out.mkdir(parents=True, exist_ok=True)
    doc = stored.calibration.to_json_dict()
    doc.update(source=stored.source, generation=stored.generation, calibration_id=stored.calibration_id,
               serial=info.serial)
    (args.out / "calibration.json").write_text(json.dumps(doc, indent=2) + "\n")
    for size in sizes:
        paths = write_camera_info(stored.calibration, args.out, size)
        print("wrote " + ", ".join(str(p) for p in paths))
    return 0


if __name__ == "__main__":
    sys.exit(main())
