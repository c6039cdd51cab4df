"""``python -m stereocam.device_sim --serve pty|tcp:HOST:PORT [--scene board] [--flash PATH]``: run a
simulated camera in its own process.

With ``--replay FILE`` the unit plays a recording back (``--fast``, ``--loop``, ``--start N``; see replay.py).

The first line on stdout is the URL a host opens. Runs until SIGINT or SIGTERM, then exits 0.
``--trigger-line NAME`` wires the unit's trigger connector to a line shared by the simulators on
this machine (a host makes one unit the master with its ``trigger_output`` parameter, SPEC §5.1);
``--truth-log PATH`` appends "sequence host_monotonic" for every exposure (the
simulator's truth, for benchmarks; never on the wire).
"""
from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path
from typing import NoReturn

from stereocam.transports.announced import announce
from stereocam.protocol.errors import ConfigError

from stereocam.protocol.firmware_image import ImageError, load_private_key

from .boot.factory import DEV_SIGNING_KEY
from .firmware import SimulatedCamera
from .links.servers import PtyServer, TcpServer
from .rig.scene import Scene
from .shared_line import SharedTriggerLine


def usage_error(message: str) -> NoReturn:
    """A bad argument: the reason on stderr and exit code 2, as the epilog promises."""
    print(f"stereocam sim: {message}", file=sys.stderr)
    raise SystemExit(2)


def build_server(spec: str, sim: SimulatedCamera) -> PtyServer | TcpServer:
    if spec == "pty":
        return PtyServer(sim)
    if spec.startswith("tcp:"):
        host, _, port = spec[4:].rpartition(":")
        if not host or not port.isdigit():
            usage_error(f"--serve tcp:HOST:PORT expected, got {spec!r}")
        return TcpServer(sim, host, int(port))
    usage_error(f"--serve takes 'pty' or 'tcp:HOST:PORT', got {spec!r}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="stereocam sim", description="Serve a simulated camera over a pty or TCP "
                                 "until SIGINT or SIGTERM (also: python -m stereocam.device_sim). The first line "
                                 "printed is the URL to open; stereocam list shows it while it runs.",
                                 epilog="Exit codes: 0 stopped by SIGINT/SIGTERM; 2 bad usage (a --serve, --scene, "
                                        "--trigger-line or --vendor-key that cannot be used).")
    ap.add_argument("--serve", required=True, metavar="pty|tcp:HOST:PORT")
    ap.add_argument("--seed", type=int, default=0, help="which simulated unit")
    ap.add_argument("--serial", default=None, help="serial number (default derived from the seed)")
    ap.add_argument("--flash", type=Path, default=None, metavar="PATH",
                    help="file behind the unit's flash, kept across restarts (created erased if missing); "
                         "default: a private file removed at exit")
    ap.add_argument("--scene", choices=[s.value for s in Scene], default=Scene.LAB.value,
                    help="what the rig looks at (board: the calibration fixture's chessboard)")
    ap.add_argument("--trigger-line", metavar="NAME", help="wire the trigger connector to the machine-wide line NAME "
                    "(the unit a host sets trigger_output=1 on drives it)")
    ap.add_argument("--truth-log", metavar="PATH", help="append each exposure's true instant to PATH")
    ap.add_argument("--replay", default=None, metavar="FILE", help="play this recording back as the unit")
    ap.add_argument("--fast", action="store_true", help="replay as fast as the host reads (default: recorded speed)")
    ap.add_argument("--loop", action="store_true", help="replay in a loop (default: once)")
    ap.add_argument("--start", type=int, default=0, help="replay from this frame index")
    ap.add_argument("--vendor-key", type=Path, default=None,
                    help="PEM Ed25519 key the factory provisions and signs the shipped image with "
                         "(default: the simulator's development key)")
    args = ap.parse_args(argv)
    try:
        line = SharedTriggerLine(args.trigger_line) if args.trigger_line else None
    except ConfigError as exc:
        usage_error(f"--trigger-line: {exc}")
    try:
        key = load_private_key(args.vendor_key.read_bytes()) if args.vendor_key else DEV_SIGNING_KEY
    except (OSError, ImageError) as exc:
        usage_error(f"--vendor-key {args.vendor_key}: {exc.strerror if isinstance(exc, OSError) else exc}")
    source = None
    if args.replay:
        from .replay import ReplaySource

        source = ReplaySource(args.replay, realtime=not args.fast, loop=args.loop, start=args.start)
    sim = SimulatedCamera(serial=args.serial, seed=args.seed, scene=args.scene, trigger_line=line, vendor_key=key,
                          source=source, flash_path=args.flash)
    truth_log = open(args.truth_log, "a", buffering=1) if args.truth_log else None
    if truth_log is not None:
        log = truth_log

        def log_exposure(seq: int, t: float) -> None:
            log.write(f"{seq} {t!r}\n")

        sim.truth.on_exposure = log_exposure
    server = build_server(args.serve, sim)

    def stop(signum, frame):
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
        if line is not None:
            line.close()
        if truth_log is not None:
            truth_log.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
