"""The ``stereocam`` command: one subcommand per tool module."""
from __future__ import annotations

import importlib
import sys

import stereocam

COMMANDS = {
    "sim": ("stereocam.device_sim.__main__", "serve a simulated camera (pty or tcp), like python -m device_sim"),
    "list": ("stereocam.tools.list_devices", "list cameras: USB (real and simulated), camera serial ports, simulators"),
    "info": ("stereocam.tools.info", "print a camera's info, configuration and counters"),
    "capture": ("stereocam.tools.capture", "save frames: left/right PNG, disparity PNG + .npy, point cloud .ply"),
    "calibrate": ("stereocam.tools.calibrate", "factory stereo calibration: from a camera (written + verified) or images"),
    "demo": ("stereocam.tools.demo", "simulator + streaming + outputs in ./out + summary"),
    "conformance": ("stereocam.tools.conformance.cli", "hold a camera to the protocol: one line per check, JUnit/JSON"),
    "record": ("stereocam.tools.record", "record a camera to an MCAP file (ROS 2 profile)"),
    "recording": ("stereocam.tools.recording", "recording files: info, repair, export"),
    "rematch": ("stereocam.tools.rematch", "re-run matching over recordings on a Dask cluster"),
    "bench": ("stereocam.tools.bench", "benchmarks: protocol decode, transports (incl. USB), matching core"),
}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in COMMANDS:
        print("usage: stereocam COMMAND [args]   (stereocam COMMAND --help for more)\n")
        for name, (_, text) in COMMANDS.items():
            print(f"  {name:<10} {text}")
        return 0 if argv and argv[0] in ("-h", "--help") else 2
    module = importlib.import_module(COMMANDS[argv[0]][0])
    try:
        return module.main(argv[1:]) or 0
    except stereocam.StereoCamError as exc:
        print(f"stereocam {argv[0]}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
