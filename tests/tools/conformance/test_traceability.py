"""SPEC.md and the conformance suite are held together by rule ids: every normative device rule
carries ``[R-<section>-<n>: check, ...]`` naming the checks that enforce it (or ``unchecked``), and
every check cites the rule ids it enforces. An orphan on either side fails here."""
from __future__ import annotations

import re

import pytest

from stereocam.tools.conformance.registry import CHECKS
from tests.support import paths

SPEC = (paths.REPO / "protocol" / "SPEC.md").read_text(encoding="utf-8")
TAG = re.compile(r"\[(R-[\d.]+-\d+): ([^\]]+)\]")
RULES: dict[str, set[str]] = {}
for _rid, _names in TAG.findall(SPEC):
    RULES.setdefault(_rid, set()).update(n.strip() for n in _names.split(","))
BY_NAME = {c.name: c for c in CHECKS}
UNCHECKED = "unchecked"


def test_rule_ids_are_well_formed_and_plenty() -> None:
    assert len(RULES) >= 50
    loose = re.findall(r"\[R-\d[^\]]*\]", SPEC)
    assert len(loose) == len(TAG.findall(SPEC)), [t for t in loose if not TAG.fullmatch(t)]


@pytest.mark.parametrize("rid", sorted(RULES))
def test_every_rule_names_checks_that_cite_it(rid: str) -> None:
    names = RULES[rid]
    if names == {UNCHECKED}:
        return
    assert UNCHECKED not in names, f"{rid}: 'unchecked' beside check names"
    missing = sorted(n for n in names if n not in BY_NAME)
    assert not missing, f"{rid} names checks the suite does not have: {missing}"
    silent = sorted(n for n in names if rid not in BY_NAME[n].rules)
    assert not silent, f"{rid} names checks that do not cite it: {silent}"


@pytest.mark.parametrize("name", [c.name for c in CHECKS])
def test_every_check_cites_rules_that_name_it(name: str) -> None:
    chk = BY_NAME[name]
    assert chk.rules, f"{name} cites no SPEC rule"
    unknown = [r for r in chk.rules if r not in RULES]
    assert not unknown, f"{name} cites rule ids SPEC.md does not have: {unknown}"
    unnamed = [r for r in chk.rules if name not in RULES[r]]
    assert not unnamed, f"{name} cites rules whose SPEC tag does not name it: {unnamed}"


def test_decided_items_of_issue_21_have_their_rules() -> None:
    """The rules the firmware implementer had to guess, each with a check that is not 'unchecked'."""
    decided = {"R-3-5": "message timeout by arrival time", "R-9-1": "stray header vs watchdog",
               "R-9-3": "first-frame deadline", "R-4.3-1": "duplicate ids", "R-4.4-3": "pending trigger",
               "R-4.6-2": "STOP discards", "R-12.1-1": "generation after restore",
               "R-12.4-1": "partial commit", "R-9-4": "second client's NACK", "R-4.0-3": "capability groups",
               "R-5.1-2": "capability-bound values"}
    for rid, what in decided.items():
        assert RULES.get(rid, {UNCHECKED}) != {UNCHECKED}, f"{what} ({rid}) has no check"
