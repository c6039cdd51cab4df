"""Click parameter types and settings every ``stereocam`` command shares."""
from __future__ import annotations

import functools
import math
import operator
import re
from pathlib import Path
from typing import Any

import click

from stereocam.protocol.params import BY_NAME, Output
from stereocam.tools.exit_codes import EXIT_CODES

CONTEXT = {"help_option_names": ["-h", "--help"], "max_content_width": 100}
"""Context settings of every command: -h as --help, lines up to 100 columns."""


class Setting(click.ParamType):
    """``NAME=VALUE``, a camera or matching parameter, as the pair (name, value): an integer, or
    one of the names the parameter table gives its values (``trigger_mode=software``, any case),
    or for ``outputs`` planes joined by ``+`` (``outputs=left+disparity``), as ``info`` prints them."""

    name = "NAME=VALUE"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> tuple[str, int]:
        if isinstance(value, tuple):
            return value
        name, _, text = str(value).partition("=")
        try:
            return name, int(text)
        except ValueError:
            pass
        known = _value_names(name)
        word = text.strip().lower()
        if name == "outputs" and word:
            try:
                return name, int(functools.reduce(operator.or_, (Output[p.upper()] for p in word.split("+"))))
            except KeyError:
                pass
        elif word in known:
            return name, known[word]
        if known:
            self.fail(f"{name} takes {', '.join(known)} or an integer, got {text!r}", param, ctx)
        self.fail(f"takes name=integer, got {value!r}", param, ctx)


def _value_names(name: str) -> dict[str, int]:
    """Parameter ``name``'s value names (lower case) -> values; ``outputs``: its planes."""
    if name == "outputs":
        return {m.name.lower(): int(m) for m in Output if m.name}
    param = BY_NAME.get(name)
    return {n.lower(): int(v) for v, n in param.values.items()} if param is not None else {}


SETTING = Setting()


INPUT_FILE = click.Path(exists=True, dir_okay=False, path_type=Path)
"""An input file argument or option: it must exist and not be a folder, given as a Path."""


def multiple_of_16(ctx: click.Context, param: click.Parameter, value: int | None) -> int | None:
    """Callback of a disparity count option: a multiple of 16 (the engines' unit), or a usage error."""
    if value is not None and value % 16:
        raise click.BadParameter(f"{value} is not a multiple of 16")
    return value


class Finite(click.FloatRange):
    """A click.FloatRange that also refuses NaN and infinities (a NaN passes every bound: a NaN gate
    would pass everything, a NaN duration never ends)."""

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> float:
        number: float = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return number


def output_file(ctx: click.Context, param: click.Parameter, value: str | None) -> Path | None:
    """Callback of an option naming a file written after the work (``type=click.Path(path_type=str)``:
    click turns '' into '.'): a non-empty name in a folder that exists and takes a file now, else a
    usage error before any work."""
    from stereocam.tools.camera.session import writable_dir

    if value is None:
        return None
    if not value.strip():
        raise click.BadParameter("must name a file, got an empty value")
    path = Path(value)
    if not path.parent.is_dir():
        raise click.BadParameter(f"{path.parent} is not a folder")
    try:  # a file written into the folder now: permission bits say nothing to root, /proc takes no file
        writable_dir(path.parent)
    except OSError as exc:
        raise click.BadParameter(exc.strerror or str(exc)) from exc
    return path


def epilog(own: str = "") -> str:
    """The ``--help`` epilog: a command's own exit codes (if any), then the shared ones."""
    return f"{own}\n\n{EXIT_CODES}" if own else EXIT_CODES


class Size(click.ParamType):
    """``WxH`` in pixels, e.g. 640x480, as (width, height)."""

    name = "WxH"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> tuple[int, int]:
        if isinstance(value, tuple):
            return value
        m = re.fullmatch(r"(\d{1,6})[xX](\d{1,6})", str(value))
        if not m:
            self.fail(f"expected WxH, e.g. 640x480, got {value!r}", param, ctx)
        if int(m.group(1)) < 1 or int(m.group(2)) < 1:
            self.fail(f"both sides must be at least 1 px, got {value!r}", param, ctx)
        return int(m.group(1)), int(m.group(2))


SIZE = Size()
