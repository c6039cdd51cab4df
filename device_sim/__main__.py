"""``python -m stereocam.device_sim --serve pty|tcp:HOST:PORT [--scene board] [--flash PATH]``: run a simulated camera in its own process.

The first line on stdout is the URL a host opens. Runs until SIGINT or SIGTERM, then exits 0.
"""
from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path

from stereocam.transports.announced import announce

from .firmware import SimulatedCamera
from .links.servers import PtyServer, TcpServer
from .rig.scene import Scene


def build_server(spec: str, sim: SimulatedCamera) -> PtyServer | TcpServer:
    if spec == "pty":
        return PtyServer(sim)
    if spec.startswith("tcp:"):
        host, _, port = spec[4:].rpartition(":")
        if not host or not port.isdigit():
            raise SystemExit(f"--serve tcp:HOST:PORT expected, got {spec!r}")
        return TcpServer(sim, host, int(port))
    raise SystemExit(f"--serve takes 'pty' or 'tcp:HOST:PORT', got {spec!r}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="stereocam sim", description="Serve a simulated camera over a pty or TCP "
                                 "until SIGINT or SIGTERM (also: python -m stereocam.device_sim). The first line "
                                 "printed is the URL to open; stereocam list shows it while it runs.")
    ap.add_argument("--serve", required=True, metavar="pty|tcp:HOST:PORT")
    ap.add_argument("--seed", type=int, default=0, help="which simulated unit")
    ap.add_argument("--serial", default=None, help="serial number (default derived from the seed)")
    ap.add_argument("--flash", type=Path, default=None, metavar="PATH",
                    help="file behind the unit's flash, kept across restarts (created erased if missing); "
                         "default: a private file removed at exit")
    ap.add_argument("--scene", choices=[s.value for s in Scene], default=Scene.LAB.value,
                    help="what the rig looks at (board: the calibration fixture's chessboard)")
    args = ap.parse_args(argv)
    sim = SimulatedCamera(serial=args.serial, seed=args.seed, scene=args.scene, flash_path=args.flash)
    server = build_server(args.serve, sim)

    def stop(signum, frame):  # noqa: ARG001
        server.shutdown()

    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    print(server.url, flush=True)
    try:
        with announce(server.url, sim.serial, sim.model, sim.firmware_version, "pty" if args.serve == "pty" else "tcp"):
            server.serve_forever()
    finally:
        server.close()
        sim.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
