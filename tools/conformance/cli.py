"""Hold a camera to the protocol: ``stereocam conformance URL [--junit FILE] [--json]``.

One line per check (PASS / FAIL / SKIP with the reason), then a summary. Exit status 0 only when
every applicable check passed. The device is left stopped, configured and calibrated as found.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Callable

import click

from stereocam.arguments import timeout_arg
from stereocam.protocol.errors import ConfigError
from stereocam.tools.options import CONTEXT, Finite, epilog, output_file

from . import report
from .results import CheckResult
from .runner import run_suite

ALWAYS = ("identity.connect", "session.restored")
"""Results every run reports, whatever -k selects."""
MAX_TIMEOUT = 60.0  # s: the longest reply deadline (SPEC §7 holds a device to well inside 1 s)


def _timeout(ctx: click.Context, param: click.Parameter, value: float) -> float:
    """``--timeout`` as the transports take it: checked by the same rule as ``stereocam.open``'s
    timeout (after Finite's range)."""
    try:
        return timeout_arg(value)
    except ConfigError as exc:
        raise click.BadParameter(str(exc)) from exc


def _pattern(ctx: click.Context, param: click.Parameter, value: str | None) -> Callable[[str], bool] | None:
    if not value:
        return None
    try:
        pattern = re.compile(value)
    except re.error as exc:
        raise click.BadParameter(f"not a regular expression: {exc}") from None
    return lambda name: pattern.search(name) is not None


@click.command("conformance", context_settings=CONTEXT,
               epilog=epilog("Exit codes: 0 every applicable check passed; 1 a check failed or the camera could "
                             "not be reached; 2 bad usage (also a -k that selects no check)."))
@click.argument("url")
@click.option("--junit", type=click.Path(dir_okay=False, path_type=str), default=None, callback=output_file,
              help="Also write the results as JUnit XML to this file.")
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON instead of text.")
@click.option("--timeout", type=Finite(0, MAX_TIMEOUT, min_open=True), default=1.0, show_default=True,
              callback=_timeout, help="Reply deadline the device is held to, seconds (SPEC §7: well inside 1 s).")
@click.option("-k", "only", metavar="REGEX", default=None, callback=_pattern,
              help="Run only the checks whose name matches.  [default: every check]")
def command(url: str, junit: Path | None, as_json: bool, timeout: float, only: Callable[[str], bool] | None) -> int:
    """Hold a camera to the protocol: one line per check (PASS / FAIL / SKIP with the reason), then a
    summary. The device is left stopped, configured and calibrated as found. URL: usb://?serial=...,
    socket://HOST:PORT, /dev/ttyACM0, ..."""
    selected: list[CheckResult] = []

    def show(result: CheckResult) -> None:
        if result.name not in ALWAYS:
            selected.append(result)
        elif only is not None and not selected and result.name == "session.restored":
            return  # nothing was selected: refused below, without a line about it
        if not as_json:
            click.echo(report.text_line(result))

    suite = run_suite(url, timeout, on_result=show, only=only)
    if only is not None and not selected and suite.device:
        raise click.BadParameter("selects no check", param_hint="-k")
    click.echo(report.to_json(suite) if as_json else report.summary(suite))
    if junit is not None:
        report.write_junit(suite, str(junit))
    return 0 if suite.passed else 1
