"""Every command and subcommand of the stereocam tree documents itself: a description, the exit
codes, and the default of every option that has one."""
from __future__ import annotations

import importlib
from collections.abc import Iterator

import click
import pytest

from stereocam.tools.cli import COMMANDS
from stereocam.tools.options import Finite


def _tree(name: str, command: click.Command) -> Iterator[tuple[str, click.Command]]:
    yield name, command
    if isinstance(command, click.Group):
        ctx = click.Context(command)
        for sub in command.list_commands(ctx):
            yield from _tree(f"{name} {sub}", command.get_command(ctx, sub))


UNSET = getattr(click.core, "UNSET", None)  # click >= 8.2: an option given no default at all

COMMAND_TREE = [pair for name, (module, _) in COMMANDS.items()
                for pair in _tree(name, importlib.import_module(module).command)]


@pytest.mark.parametrize("name, command", COMMAND_TREE, ids=[name for name, _ in COMMAND_TREE])
def test_help_has_a_description_exit_codes_and_defaults(name, command):
    assert command.help and len(command.help.split()) >= 4, f"{name}: no description"
    assert command.epilog and "Exit codes" in command.epilog, f"{name}: no exit codes"
    for option in command.params:
        if not isinstance(option, click.Option) or option.is_flag or option.count:
            continue
        assert option.help, f"{name} {option.opts[0]}: no help"
        has_default = not option.required and option.default not in (None, (), UNSET)
        assert not has_default or option.show_default, f"{name} {option.opts[0]}: default {option.default!r} not shown"


@pytest.mark.parametrize("name, command", COMMAND_TREE, ids=[name for name, _ in COMMAND_TREE])
def test_every_number_option_refuses_nan_and_infinities(name, command):
    """click.FloatRange lets NaN through every bound (a NaN duration never ends, a NaN shift is
    garbage): each float option is options.Finite, which refuses NaN and infinities at parse time."""
    for option in command.params:
        if isinstance(option.type, click.FloatRange):
            assert isinstance(option.type, Finite), f"{name} {option.opts[0]}: a bare FloatRange"
            with pytest.raises(click.BadParameter, match="not a finite number"):
                option.type.convert("nan", option, None)
