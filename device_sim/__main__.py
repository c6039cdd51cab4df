"""``python -m stereocam.device_sim --serve pty|tcp:HOST:PORT [--scene board]``: run a simulated camera in its own process.

With ``--replay FILE`` the unit plays a recording back (``--fast``, ``--loop``, ``--start N``; see replay.py).

The first line on stdout is the URL a host opens. Runs until SIGINT or SIGTERM, then exits 0.
``--trigger-line NAME`` wires the unit's trigger input to a line shared by the simulators on this
machine; ``--trigger-master FPS`` makes this unit drive that line at FPS (timed by its own
crystal); ``--truth-log PATH`` appends "sequence host_monotonic" for every exposure (the
simulator's truth, for benchmarks; never on the wire).
"""
from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path

from stereocam.transports.announced import announce
from stereocam.protocol.errors import ConfigError

from stereocam.protocol.firmware_image import load_private_key

from .boot.factory import DEV_SIGNING_KEY
from .firmware import SimulatedCamera
from .links.servers import PtyServer, TcpServer
from .rig.scene import Scene
from .shared_line import SharedTriggerLine
from .trigger import TriggerMaster


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
    ap.add_argument("--scene", choices=[s.value for s in Scene], default=Scene.LAB.value,
                    help="what the rig looks at (board: the calibration fixture's chessboard)")
    ap.add_argument("--trigger-line", metavar="NAME", help="join the machine-wide trigger line NAME")
    ap.add_argument("--trigger-master", type=float, metavar="FPS", help="drive the trigger line at FPS")
    ap.add_argument("--truth-log", metavar="PATH", help="append each exposure's true instant to PATH")
    ap.add_argument("--replay", default=None, metavar="FILE", help="play this recording back as the unit")
    ap.add_argument("--fast", action="store_true", help="replay as fast as the host reads (default: recorded speed)")
    ap.add_argument("--loop", action="store_true", help="replay in a loop (default: once)")
    ap.add_argument("--start", type=int, default=0, help="replay from this frame index")
    ap.add_argument("--vendor-key", type=Path, default=None,
                    help="PEM Ed25519 key the factory provisions and signs the shipped image with "
                         "(default: the simulator's development key)")
    args = ap.parse_args(argv)
    if args.trigger_master is not None and (args.trigger_line is None or not args.trigger_master > 0):
        raise SystemExit("--trigger-master FPS needs --trigger-line NAME and FPS > 0")
    try:
        line = SharedTriggerLine(args.trigger_line) if args.trigger_line else None
    except ConfigError as exc:
        raise SystemExit(f"--trigger-line: {exc}") from exc
    key = load_private_key(args.vendor_key.read_bytes()) if args.vendor_key else DEV_SIGNING_KEY
    source = None
    if args.replay:
        from .replay import ReplaySource

        source = ReplaySource(args.replay, realtime=not args.fast, loop=args.loop, start=args.start)
    sim = SimulatedCamera(serial=args.serial, seed=args.seed, scene=args.scene, trigger_line=line, vendor_key=key,
                          source=source)
    truth_log = open(args.truth_log, "a", buffering=1) if args.truth_log else None  # noqa: SIM115
    if truth_log is not None:
        sim.truth.on_exposure = lambda seq, t: truth_log.write(f"{seq} {t!r}\n")
    master = TriggerMaster(line, args.trigger_master, sim.clock) if args.trigger_master else None
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
        if master is not None:
            master.close()
        server.close()
        sim.close()
        if line is not None:
            line.close()
        if truth_log is not None:
            truth_log.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
