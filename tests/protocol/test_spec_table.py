"""SPEC §5.1's parameter table says what protocol/params.py's rows say: id, name, default, range,
step / odd / one of, unit and live, row for row (a firmware team builds from the text)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from stereocam.protocol.params import PARAMS, Param

SPEC = Path(__file__).resolve().parents[2] / "protocol" / "SPEC.md"
UNITS = {"us": "µs"}  # the code's ASCII spelling -> the text's


def _number(text: str) -> int:
    return int(text.replace("−", "-").replace(" ", ""))


def spec_rows() -> dict[int, list[str]]:
    text = SPEC.read_text(encoding="utf-8")
    table = text[text.index("### §5.1 Table"):]
    table = table[:table.index("\n\n", table.index("| id |"))]
    rows = {}
    for line in table.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells and cells[0].isdigit():
            rows[int(cells[0])] = cells
    return rows


def test_the_table_lists_every_parameter_once() -> None:
    assert sorted(spec_rows()) == sorted(p.pid for p in PARAMS)


@pytest.mark.parametrize("param", PARAMS, ids=lambda p: p.name)
def test_each_row_states_the_code_s_parameter(param: Param) -> None:
    pid, name, default, rng, rule, unit, live, _meaning = spec_rows()[param.pid]
    assert name == f"`{param.name}`"
    assert _number(re.match(r"[−\-\d ]+", default).group()) == param.default  # "(15 before 1.3)" is history
    lo, hi = rng.split("..")
    assert (_number(lo), _number(hi)) == (param.lo, param.hi)
    want = [f"step {param.step}"] if param.step > 1 else []
    want += ["odd"] if param.odd else []
    want += [f"one of {', '.join(map(str, param.one_of))}"] if param.one_of else []
    assert rule == " ".join(want)
    assert unit == UNITS.get(param.unit, param.unit)
    assert live == ("yes" if param.live else "no")
