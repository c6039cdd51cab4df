"""``stereocam list``: print the cameras this host can open (USB, serial ports, simulators)."""
from __future__ import annotations

import argparse
import json
from typing import Sequence

from stereocam.discovery import DeviceEntry, list_devices

COLUMNS = (("URL", "url"), ("TRANSPORT", "transport"), ("SERIAL", "serial"), ("MODEL", "model"),
           ("FIRMWARE", "firmware"), ("WHERE", "location"))


def format_table(entries: Sequence[DeviceEntry]) -> str:
    """A plain text table, one camera a line; simulated USB devices are marked with "(sim)"."""
    rows = [[title for title, _ in COLUMNS]]
    for e in entries:
        row = ["" if getattr(e, key) is None else str(getattr(e, key)) for _, key in COLUMNS]
        if e.simulated:
            row[1] += " (sim)"
        rows.append(row)
    widths = [max(len(r[i]) for r in rows) for i in range(len(COLUMNS))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="stereocam list", description=__doc__)
    parser.add_argument("--json", action="store_true", help="print a JSON array instead")
    args = parser.parse_args(argv)
    entries = list_devices()
    if args.json:
        print(json.dumps([e.as_dict() for e in entries], indent=2))
    elif entries:
        print(format_table(entries))
    else:
        print("no cameras found (USB, serial ports, simulators)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
