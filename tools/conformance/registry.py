"""The check table: checks register themselves, in the order they run, by decorator."""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Iterable

if TYPE_CHECKING:
    from .context import Context

CheckFn = Callable[["Context"], "str | None"]
FamilyFn = Callable[["Context"], Iterable[tuple[str, CheckFn]]]


@dataclass(frozen=True)
class Check:
    name: str  # "area.what"
    fn: CheckFn
    rules: tuple[str, ...]  # the SPEC rule ids ("R-4.3-1") this check enforces

    @property
    def area(self) -> str:
        return self.name.split(".", 1)[0]


@dataclass(frozen=True)
class Family:
    name: str  # "area.what"
    fn: FamilyFn  # lists (suffix, check) pairs, each run and reported as name.suffix
    rules: tuple[str, ...]  # the SPEC rule ids ("R-4.3-1") its checks enforce

    @property
    def area(self) -> str:
        return self.name.split(".", 1)[0]


CHECKS: list[Check | Family] = []


def check(name: str, *rules: str) -> Callable[[CheckFn], CheckFn]:
    """Register a check enforcing SPEC ``rules``: it returns a detail line (or None) on pass,
    raises CheckFailed/CheckSkipped."""
    def register(fn: CheckFn) -> CheckFn:
        CHECKS.append(Check(name, fn, rules))
        return fn
    return register


def family(name: str, *rules: str) -> Callable[[FamilyFn], FamilyFn]:
    """Register a family enforcing SPEC ``rules``: called once, it lists (suffix, check) pairs,
    e.g. one per parameter."""
    def register(fn: FamilyFn) -> FamilyFn:
        CHECKS.append(Family(name, fn, rules))
        return fn
    return register
