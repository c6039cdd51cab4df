"""The option types every command shares (tools/options.py)."""
from __future__ import annotations

import click
import pytest

from stereocam.protocol.params import Output, TriggerMode
from stereocam.tools.options import SETTING


@pytest.mark.parametrize("text, want", [
    ("fps=5", ("fps", 5)),
    ("trigger_mode=software", ("trigger_mode", int(TriggerMode.SOFTWARE))),
    ("trigger_mode=External", ("trigger_mode", int(TriggerMode.EXTERNAL))),
    ("hole_fill=background", ("hole_fill", 2)),
    ("outputs=left+disparity", ("outputs", int(Output.LEFT | Output.DISPARITY))),
    ("outputs=7", ("outputs", 7)),
])
def test_a_setting_takes_an_integer_or_the_name_info_prints(text: str, want: tuple[str, int]) -> None:
    assert SETTING.convert(text, None, None) == want


@pytest.mark.parametrize("text, word", [
    ("trigger_mode=bogus", "trigger_mode takes free_run, software, external or an integer"),
    ("outputs=left+foo", "outputs takes left, right, disparity, confidence"),
    ("fps=abc", "takes name=integer"),
    ("fps", "takes name=integer"),
])
def test_a_setting_of_no_known_value_names_the_ones_there_are(text: str, word: str) -> None:
    with pytest.raises(click.BadParameter, match=word):
        SETTING.convert(text, None, None)


@pytest.mark.parametrize("text", ["0x0", "640x0", "1234567x480", "640*480", "-640x480"])
def test_a_size_is_two_positive_sides(text: str) -> None:
    from stereocam.tools.options import SIZE
    with pytest.raises(click.BadParameter, match="WxH|at least 1 px"):
        SIZE.convert(text, None, None)
    assert SIZE.convert("640X480", None, None) == (640, 480)
