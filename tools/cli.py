"""The ``stereocam`` command: one click command tree built from the COMMANDS table.

Every module in COMMANDS exposes ``command``, a click command (or group) with its defaults and the
exit codes in its ``--help``. Adding a tool is one line. Errors are handled once, here, for every
command: see EXIT_CODES.
"""
from __future__ import annotations

import importlib
import logging
import os
import sys
from typing import Any, Sequence

import click

import stereocam
from stereocam.protocol.errors import MissingInputError
from stereocam.protocol.extras import raise_missing

from .exit_codes import EXIT_BROKEN_PIPE, EXIT_CAMERA, EXIT_CODES, EXIT_INTERRUPTED, EXIT_OK, EXIT_USAGE  # noqa: F401
from .logs import configure, parse_levels, restored

COMMANDS: dict[str, tuple[str, str]] = {
    "view": ("stereocam.tools.viewer.command", "live viewer in the browser: images, disparity, depth, settings"),
    "list": ("stereocam.tools.camera.list_devices", "list cameras: USB, serial ports, served and in-process simulators"),
    "info": ("stereocam.tools.camera.info", "print a camera's identity, calibration, configuration and counters"),
    "capture": ("stereocam.tools.camera.capture", "save frames: left/right PNG, disparity PNG + .npy, point cloud .ply"),
    "match": ("stereocam.tools.match", "a disparity map from two rectified image files: PNG (KITTI), PFM or .npy"),
    "calibrate": ("stereocam.tools.calibration.calibrate", "factory stereo calibration: from a camera (written + verified) or images"),
    "calibration": ("stereocam.tools.calibration.export", "calibration export URL --size WxH: ROS camera_info from a unit"),
    "factory": ("stereocam.tools.factory.cli", "factory record: yield and metric distributions per day and station"),
    "firmware": ("stereocam.tools.firmware.cli", "signed firmware images: keygen, sign, update a camera, slot status"),
    "demo": ("stereocam.tools.demo.cli", "simulator + streaming + outputs in ./out + summary"),
    "conformance": ("stereocam.tools.conformance.cli", "hold a camera to the protocol: one line per check, JUnit/JSON"),
    "record": ("stereocam.tools.recording.record", "record a camera to an MCAP file (ROS 2 profile)"),
    "recording": ("stereocam.tools.recording.files", "recording files: info, repair, export"),
    "rematch": ("stereocam.tools.recording.rematch", "re-run matching over recordings on a Dask cluster"),
    "sim": ("stereocam.device_sim.__main__", "serve a simulated camera over a pty or TCP"),
    "bench": ("stereocam.tools.bench.cli", "benchmarks: protocol, transports, USB, matching core, calibration"),
    "soak": ("stereocam.tools.soak.cli", "long fuzz + faulty-link streaming run with crash/hang/frame counts"),
}
"""name -> (module, one-line help). The module provides ``command``."""


_log = logging.getLogger("stereocam.cli")


class CommandTable(click.Group):
    """Subcommands from COMMANDS, imported only when run; errors turned into clean exits."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return list(COMMANDS)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name not in COMMANDS:
            return None
        module_name, _ = COMMANDS[name]
        ctx.meta["stereocam.command"] = name  # for the error messages of invoke
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:  # an optional dependency group not installed
            raise_missing(exc, "this command")
        return module.command

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        with formatter.section("Commands"):
            formatter.write_dl([(name, text) for name, (_, text) in COMMANDS.items()])

    def resolve_command(self, ctx: click.Context, args: list[str]):
        name, command, rest = super().resolve_command(ctx, args)
        ctx.meta["stereocam.command"] = name  # for the error messages below
        return name, command, rest

    def invoke(self, ctx: click.Context) -> Any:
        try:
            result = super().invoke(ctx)
            sys.stdout.flush()  # a closed pipe shows here, not as a traceback at exit
            return result
        except BrokenPipeError:
            devnull = os.open(os.devnull, os.O_WRONLY)  # nothing more to say to a closed pipe
            os.dup2(devnull, sys.stdout.fileno())
            raise click.exceptions.Exit(EXIT_BROKEN_PIPE) from None
        except (KeyboardInterrupt, click.Abort):
            click.echo(f"stereocam {_command(ctx)}: interrupted", err=True)
            raise click.exceptions.Exit(EXIT_INTERRUPTED) from None
        except (MissingInputError, stereocam.ConfigError) as exc:  # a missing input file, a value that cannot
            # be used (a URL without a port, a bad setting): bad usage
            click.echo(f"stereocam {_command(ctx)}: error: {exc}", err=True)
            raise click.exceptions.Exit(EXIT_USAGE) from None
        except stereocam.StereoCamError as exc:
            _log.debug("%s failed", _command(ctx), exc_info=exc)
            click.echo(f"stereocam {_command(ctx)}: error: {exc}", err=True)
            raise click.exceptions.Exit(EXIT_CAMERA) from None
        except OSError as exc:  # a path that cannot be read or written: the user's to fix
            _log.debug("%s failed", _command(ctx), exc_info=exc)
            click.echo(f"stereocam {_command(ctx)}: error: {exc}", err=True)
            raise click.exceptions.Exit(EXIT_USAGE) from None


def _command(ctx: click.Context) -> str:
    """The subcommand being run (set by CommandTable.resolve_command)."""
    return ctx.meta.get("stereocam.command", "")


def _log_levels(ctx: click.Context, param: click.Parameter, value: tuple[str, ...]) -> tuple[str, ...]:
    try:
        parse_levels(0, value)
    except ValueError as exc:
        raise click.BadParameter(str(exc)) from None
    return value


@click.group("stereocam", cls=CommandTable, epilog=EXIT_CODES, no_args_is_help=True,
             context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(stereocam.__version__, "--version", prog_name="stereocam", message="%(prog)s %(version)s")
@click.option("-v", "--verbose", count=True,
              help="Log more of stereocam's own lines to stderr: -v info (reconnects, CRC errors, drops), -vv debug.  "
                   "[default: warnings only]")
@click.option("--log-level", "log_levels", multiple=True, metavar="[NAME=]LEVEL", callback=_log_levels,
              help="LEVEL (ERROR, WARNING, INFO, DEBUG) for stereocam's loggers, overriding -v; NAME=LEVEL for "
                   "another library's logger, e.g. distributed=INFO (repeatable).  [default: other libraries "
                   "at WARNING]")
@click.pass_context
def cli(ctx: click.Context, verbose: int, log_levels: tuple[str, ...]) -> None:
    """Tools for STOC-class stereo cameras and their simulator. Run a command with --help for more."""
    configure(parse_levels(verbose, log_levels))
    _log.debug("stereocam %s (Python %s): %s", stereocam.__version__, sys.version.split()[0], ctx.invoked_subcommand)


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``stereocam`` with ``argv``; returns the exit code (see EXIT_CODES)."""
    args = list(sys.argv[1:] if argv is None else argv)
    try:
        with restored():
            rc = cli.main(args=args, prog_name="stereocam", standalone_mode=False)
    except click.ClickException as exc:  # usage errors, bad parameters: before any camera is touched
        exc.show()
        return exc.exit_code
    except click.Abort:
        click.echo("stereocam: interrupted", err=True)
        return EXIT_INTERRUPTED
    return rc if isinstance(rc, int) else EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
