"""Hold a camera to the protocol: ``stereocam conformance URL [--junit FILE] [--json]``.

One line per check (PASS / FAIL / SKIP with the reason), then a summary. Exit status 0 only when
every applicable check passed. The device is left stopped, configured and calibrated as found.
"""
from __future__ import annotations

import argparse
import re
import sys

from . import report
from .results import CheckResult
from .runner import run_suite


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="stereocam conformance", description=__doc__.split("\n\n")[1],
                                 epilog="Exit codes: 0 every applicable check passed; 1 a check failed or the "
                                        "camera could not be reached; 2 bad usage.")
    ap.add_argument("url", help="camera URL (usb://?serial=..., socket://host:port, /dev/ttyACM0, ...)")
    ap.add_argument("--junit", metavar="FILE", help="also write the results as JUnit XML")
    ap.add_argument("--json", action="store_true", help="print the results as JSON instead of text")
    ap.add_argument("--timeout", type=float, default=1.0,
                    help="reply deadline the device is held to, seconds (SPEC §7: well inside 1 s)")
    ap.add_argument("-k", metavar="REGEX", help="run only the checks whose name matches")
    args = ap.parse_args(argv)
    if not args.timeout > 0:
        ap.error("--timeout must be a positive number of seconds")
    try:
        only = re.compile(args.k).search if args.k else None
    except re.error as exc:
        ap.error(f"-k: not a regular expression: {exc}")

    def show(result: CheckResult) -> None:
        if not args.json:
            print(report.text_line(result), flush=True)

    suite = run_suite(args.url, args.timeout, on_result=show, only=only)
    if args.json:
        print(report.to_json(suite))
    else:
        print(report.summary(suite))
    if args.junit:
        report.write_junit(suite, args.junit)
    return 0 if suite.passed else 1


if __name__ == "__main__":
    sys.exit(main())
