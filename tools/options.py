"""Click parameter types and settings every ``stereocam`` command shares."""
from __future__ import annotations

import re
from typing import Any

import click

from stereocam.tools.exit_codes import EXIT_CODES

CONTEXT = {"help_option_names": ["-h", "--help"], "max_content_width": 100}
"""Context settings of every command: -h as --help, lines up to 100 columns."""


class Setting(click.ParamType):
    """``NAME=INTEGER``, a camera or matching parameter, as the pair (name, value)."""

    name = "NAME=VALUE"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> tuple[str, int]:
        if isinstance(value, tuple):
            return value
        name, _, text = str(value).partition("=")
        try:
            return name, int(text)
        except ValueError:
            self.fail(f"takes name=integer, got {value!r}", param, ctx)


SETTING = Setting()


def epilog(own: str = "") -> str:
    """The ``--help`` epilog: a command's own exit codes (if any), then the shared ones."""
    return f"{own}\n\n{EXIT_CODES}" if own else EXIT_CODES


class Size(click.ParamType):
    """``WxH`` in pixels, e.g. 640x480, as (width, height)."""

    name = "WxH"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> tuple[int, int]:
        if isinstance(value, tuple):
            return value
        m = re.fullmatch(r"(\d+)[xX](\d+)", str(value))
        if not m:
            self.fail(f"expected WxH, e.g. 640x480, got {value!r}", param, ctx)
        return int(m.group(1)), int(m.group(2))


SIZE = Size()
