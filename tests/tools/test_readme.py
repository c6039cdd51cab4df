"""The README's SDK example runs as written."""
from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parents[2] / "README.md"


def test_sdk_example_runs_as_written(tmp_path, monkeypatch, capsys):
    section = README.read_text().split("## Using the SDK", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    exec(compile(code, str(README), "exec"), {})  # the README's own example
    assert (tmp_path / "cloud.ply").stat().st_size > 1000
    assert "Frame(sequence=" in capsys.readouterr().out
