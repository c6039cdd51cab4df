"""The README's output samples are the commands' real output (issue 20: they had drifted: `protocol
1.1`, `dropped=0`). Each block after an ``<!-- output: stereocam ARGS -->`` comment is compared with
what ``stereocam ARGS`` prints now, against a simulator served for the test (``URL`` in ARGS is its
URL; ``ARGS | URL`` keeps the header and that URL's lines). What varies from run to run (counts,
rates, ports, pids, ids, column widths) is compared by shape; versions and words exactly. A ``...``
line in a sample stands for any lines.

``STEREOCAM_UPDATE_README=1`` rewrites the samples from this run instead (then review the diff)."""
from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from stereocam.device_sim.process import ServedSimulator

pytestmark = pytest.mark.sim_only("serves a simulator for the samples")

README = Path(__file__).resolve().parents[2] / "README.md"
SAMPLE = re.compile(r"<!-- output: stereocam (?P<args>.+?) -->\n```\n(?P<body>.*?)```\n", re.S)
ELIDED = "..."
_HEX_ID = re.compile(r"\b[0-9a-f]{8}\b")
_VERSION = re.compile(r"\b\d+\.\d+\.\d+\b|(?<=protocol )\d+\.\d+\b")
_NUMBER = re.compile(r"\d+")
_KEEP_UP = re.compile(r"^(kept up|this machine could not keep up): .*")  # demo's note: the machine's load decides


def shape(line: str) -> str:
    """``line`` with what varies between runs made generic; versions and words kept."""
    line = _KEEP_UP.sub("(demo's keep-up note)", _HEX_ID.sub("ID", line))
    versions = _VERSION.findall(line)
    line = _NUMBER.sub("N", _VERSION.sub("\0", line))
    for v in versions:
        line = line.replace("\0", v, 1)
    return " ".join(line.split())


def run(args: str, url: str, cwd: Path) -> list[str]:
    command, _, only = args.partition(" | ")
    argv = [a.replace("URL", url) for a in shlex.split(command)]
    r = subprocess.run([sys.executable, "-m", "stereocam.tools.cli", *argv], capture_output=True, text=True,
                       cwd=cwd, timeout=180)
    assert r.returncode == 0, (args, r.stderr)
    lines = r.stdout.splitlines()
    if only:
        lines = lines[:1] + [ln for ln in lines[1:] if only.replace("URL", url) in ln]
    return lines


def matches(sample: list[str], out: list[str]) -> bool:
    """Whether ``out`` has ``sample``'s shape, each ``...`` standing for any lines."""
    pattern = "".join(r"(?:.*\n)*?" if s == ELIDED else re.escape(shape(s)) + r"\n" for s in sample)
    return re.fullmatch(pattern, "".join(shape(ln) + "\n" for ln in out)) is not None


def updated(sample: list[str], out: list[str]) -> list[str]:
    """``sample`` from this run's output: whole, or (elided) each kept line replaced by the output's line
    with the same first word."""
    if ELIDED not in sample:
        return out
    by_key = {ln.split(" ", 1)[0]: ln for ln in reversed(out)}
    return [s if s == ELIDED else by_key.get(s.split(" ", 1)[0], s) for s in sample]


@pytest.fixture(scope="module")
def served():
    with ServedSimulator("tcp:127.0.0.1:0", seed=0) as sim:
        yield sim.url


def test_every_output_sample_in_the_readme_is_what_the_command_prints(served, tmp_path):
    text = README.read_text()
    samples = list(SAMPLE.finditer(text))
    assert len(samples) >= 3
    stale, new_text = [], text
    for sample in samples:
        lines = sample["body"].splitlines()
        out = run(sample["args"], served, tmp_path)
        if os.environ.get("STEREOCAM_UPDATE_README"):
            body = "\n".join(updated(lines, out)) + "\n"
            new_text = new_text.replace(sample.group(0), sample.group(0).replace(sample["body"], body))
        elif not matches(lines, out):
            stale.append(f"stereocam {sample['args']}:\nREADME:\n" + "\n".join(lines) + "\nnow:\n" + "\n".join(out))
    if new_text != text:
        README.write_text(new_text)
    assert not stale, "README samples differ from the output (STEREOCAM_UPDATE_README=1 rewrites them):\n\n" + \
        "\n\n".join(stale)


@pytest.mark.parametrize("sample, out, same", [
    (["protocol 1.1"], ["protocol 1.2"], False),  # a version is compared as it is
    (["summary: frames=62 dropped=0 link_errors=0"], ["summary: frames=51 dropped=7 other_dropped=1 link_errors=0"],
     False),  # a field more
    (["summary: frames=62 fps=15.4"], ["summary: frames=51 fps=9.8"], True),  # counts and rates vary
    (["model X", ELIDED, "config.fps 30", ELIDED], ["model X", "serial S", "config.fps 15", "config.gain 0"], True),
    (["calibration id 0890b30f"], ["calibration id a1b2c3d4"], True),
    (["kept up: 15.4 of the 15 fps asked for"], ["this machine could not keep up: 9.1 of the 15 fps ..."], True)])
def test_samples_are_compared_by_shape(sample, out, same):
    assert matches(sample, out) is same
