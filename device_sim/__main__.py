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

import contextlib
import os
import signal
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Iterator, NoReturn

import click

from stereocam.protocol.errors import ConfigError
from stereocam.protocol.firmware_image import ImageError, load_private_key
from stereocam.transports import announced
from stereocam.transports.announced import announce

from .boot.factory import DEV_SIGNING_KEY
from .firmware import SimulatedCamera
from .links.inprocess import SEED_MAX
from .links.servers import PORT_MAX, PtyServer, TcpServer
from .rig.lens import LensClass
from .rig.scene import Scene
from .shared_line import SharedTriggerLine


def usage_error(message: str) -> NoReturn:
    """A bad argument: the reason on stderr and exit code 2, as the epilog promises."""
    raise click.UsageError(message)


@contextlib.contextmanager
def free_seed() -> Iterator[int]:
    """The lowest seed no other simulator served on this machine by this user has claimed, claimed by
    this process (a file in the announce directory, created exclusively) until the block ends; a claim
    whose process is gone is taken over."""
    folder = announced.runtime_dir()
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    seed = 0
    while True:
        path = folder / f"seed-{seed}.claim"
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600)
        except FileExistsError:
            try:
                owner = int(path.read_text() or "0")
            except (OSError, ValueError):
                owner = 0
            if owner and announced.pid_alive(owner):
                seed += 1
            elif owner:  # left by a killed simulator: remove it and try this seed again
                path.unlink(missing_ok=True)
            else:  # another process is writing its claim right now
                seed += 1
            continue
        with os.fdopen(fd, "w") as f:
            f.write(str(os.getpid()))
        try:
            yield seed
        finally:
            path.unlink(missing_ok=True)
        return


def serve_spec(spec: str) -> tuple[str, int] | None:
    """``--serve``'s value: None for ``pty``, else the (host, port) of ``tcp:HOST:PORT`` with a port
    0..65535; anything else a usage error (checked before the simulator is built: that is slow)."""
    if spec == "pty":
        return None
    if spec.startswith("tcp:"):
        host, _, port = spec[4:].rpartition(":")
        if not host or not (port.isascii() and port.isdigit()):
            usage_error(f"--serve tcp:HOST:PORT expected, got {spec!r}")
        if int(port) > PORT_MAX:
            usage_error(f"--serve {spec!r}: the port must be 0..{PORT_MAX} (0: any free port), got {port}")
        return host, int(port)
    usage_error(f"--serve takes 'pty' or 'tcp:HOST:PORT', got {spec!r}")


def _check_serve(ctx: click.Context, param: click.Parameter, value: str) -> str:
    serve_spec(value)
    return value


def build_server(spec: str, sim: SimulatedCamera) -> PtyServer | TcpServer:
    """The server ``spec`` names, listening; a port that is taken or a host that is not this machine's
    (OSError from the bind) is a usage error too."""
    address = serve_spec(spec)
    try:
        return PtyServer(sim) if address is None else TcpServer(sim, *address)
    except OSError as exc:
        raise click.UsageError(f"--serve {spec!r}: cannot listen there: {exc.strerror or exc}") from exc


@click.command("sim", context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
               epilog="Exit codes: 0 stopped by SIGINT/SIGTERM; 2 bad usage (a --serve, --scene, --trigger-line "
                      "or --vendor-key that cannot be used).")
@click.option("--serve", required=True, metavar="pty|tcp:HOST:PORT", callback=_check_serve,
              help="Where to serve the unit (PORT 0..65535; 0: any free port).")
@click.option("--seed", type=click.IntRange(0, SEED_MAX), default=None,
              help="Which simulated unit (its serial is SIM<seed>).  [default: the lowest no other simulator "
                   "served on this machine has, so serials are unique]")
@click.option("--serial", default=None, help="Serial number.  [default: derived from the seed]")
@click.option("--flash", type=click.Path(dir_okay=False, path_type=Path), default=None, metavar="PATH",
              help="File behind the unit's flash, kept across restarts (created erased if missing).  "
                   "[default: a private file removed at exit]")
@click.option("--scene", type=click.Choice([s.value for s in Scene]), default=Scene.LAB.value, show_default=True,
              help="What the rig looks at (board: the calibration fixture's chessboard).")
@click.option("--lens", type=click.Choice([c.value for c in LensClass]), default=LensClass.STANDARD.value,
              show_default=True, help="The unit's lens class (wide: 120 deg rational; fisheye: 180 deg equidistant).")
@click.option("--trigger-line", metavar="NAME", default=None,
              help="Wire the trigger connector to the machine-wide line NAME (the unit a host sets "
                   "trigger_output=1 on drives it).")
@click.option("--truth-log", metavar="PATH", default=None, help="Append each exposure's true instant to PATH.")
@click.option("--replay", default=None, metavar="FILE", help="Play this recording back as the unit.")
@click.option("--fast", is_flag=True, help="Replay as fast as the host reads.  [default: recorded speed]")
@click.option("--loop", is_flag=True, help="Replay in a loop.  [default: once]")
@click.option("--start", type=click.IntRange(min=0), default=0, show_default=True, help="Replay from this frame index.")
@click.option("--vendor-key", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="PEM Ed25519 key the factory provisions and signs the shipped image with.  "
                   "[default: the simulator's development key]")
def command(**params: Any) -> int:
    """Serve a simulated camera over a pty or TCP until SIGINT or SIGTERM (also: python -m
    stereocam.device_sim). The first line printed is the URL to open; stereocam list shows it while
    it runs."""
    args = SimpleNamespace(**params)
    if args.replay and args.seed is None:  # the recorded unit's serial: no seed to claim
        args.seed = 0
    if args.seed is not None:
        return serve(args)
    with free_seed() as seed:
        args.seed = seed
        return serve(args)


def serve(args: SimpleNamespace) -> int:
    """Serve the unit ``args`` describe until SIGINT or SIGTERM; returns 0."""
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
                          source=source, flash_path=args.flash, lens=args.lens)
    truth_log = open(args.truth_log, "a", buffering=1) if args.truth_log else None
    if truth_log is not None:
        log = truth_log

        def log_exposure(seq: int, t: float) -> None:
            log.write(f"{seq} {t!r}\n")

        sim.truth.on_exposure = log_exposure
    server: PtyServer | TcpServer | None = None
    try:
        server = listening = build_server(args.serve, sim)

        def stop(signum, frame):
            listening.shutdown()

        signal.signal(signal.SIGINT, stop)
        signal.signal(signal.SIGTERM, stop)
        print(server.url, flush=True)
        with announce(server.url, sim.serial, sim.model, sim.firmware_version, "pty" if args.serve == "pty" else "tcp"):
            server.serve_forever()
    finally:
        if server is not None:
            server.close()
        sim.close()
        if line is not None:
            line.close()
        if truth_log is not None:
            truth_log.close()
    return 0


if __name__ == "__main__":
    command.main(prog_name="stereocam sim")
