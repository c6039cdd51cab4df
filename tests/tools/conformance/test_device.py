"""The conformance suite as device tests: each check against every transport, or ``--device URL``.

One source of truth: the checks ``stereocam conformance`` runs are the checks pytest runs, so
a firmware team's board is held to the same rules whichever way they run them.
"""
from __future__ import annotations

import pytest

from stereocam.tools.conformance.registry import CHECKS
from stereocam.tools.conformance.results import Outcome
from stereocam.tools.conformance.runner import run_suite

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("name", [c.name for c in CHECKS])
def test_conformance_check(device_url, name):
    suite = run_suite(device_url, timeout=1.0, only=lambda n: n == name or n.startswith(name + "."))
    mine = [r for r in suite.results if r.name == name or r.name.startswith(name + ".")]
    bad = [f"{r.name}: {r.detail}" for r in suite.results if r.outcome in (Outcome.FAIL, Outcome.ERROR)]
    assert not bad, "\n".join(bad)
    if mine and all(r.outcome == Outcome.SKIP for r in mine):
        pytest.skip("; ".join(f"{r.name}: {r.detail}" for r in mine))
    assert mine, f"the suite ran nothing for {name}"
