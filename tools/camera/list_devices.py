"""stereocam list: print the cameras this host can open (USB, serial ports, served and in-process simulators)."""
from __future__ import annotations

import json
from typing import Sequence

import click

from stereocam.discovery import DeviceEntry, list_devices
from stereocam.tools.options import CONTEXT, epilog

COLUMNS = (("URL", "url"), ("TRANSPORT", "transport"), ("SERIAL", "serial"), ("MODEL", "model"),
           ("FIRMWARE", "firmware"), ("WHERE", "location"))


def format_table(entries: Sequence[DeviceEntry]) -> str:
    """A plain text table, one camera a line; simulated devices are marked with "(sim)"."""
    rows = [[title for title, _ in COLUMNS]]
    for e in entries:
        row = ["" if getattr(e, key) is None else str(getattr(e, key)) for _, key in COLUMNS]
        if e.simulated:
            row[1] += " (sim)"
        rows.append(row)
    widths = [max(len(r[i]) for r in rows) for i in range(len(COLUMNS))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows)


@click.command("list", epilog=epilog("Exit codes: 0 also when no camera was found."), context_settings=CONTEXT)
@click.option("--json", "as_json", is_flag=True, help="Print a JSON array instead of a table.")
def command(as_json: bool) -> int:
    """Print the cameras this host can open: USB cameras (real and simulated), camera serial ports,
    simulators served on this machine over TCP or a pty (stereocam sim), in-process simulators.
    Each URL opens with stereocam info URL."""
    entries = list_devices()
    if as_json:
        click.echo(json.dumps([e.as_dict() for e in entries], indent=2))
    elif entries:
        click.echo(format_table(entries))
    else:
        click.echo("no cameras found (USB, serial ports, simulators)")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Run as ``stereocam list ARGV``; returns the exit code."""
    return command.main(args=list(argv or []), prog_name="stereocam list", standalone_mode=False)
