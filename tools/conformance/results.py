"""What a conformance run produces: one result per check, and the run as a whole."""
from __future__ import annotations

import enum
from dataclasses import dataclass, field


class Outcome(enum.Enum):
    PASS = "PASS"
    FAIL = "FAIL"
    SKIP = "SKIP"  # not applicable to this device (not advertised), with the reason
    ERROR = "ERROR"  # the suite itself failed while judging; counts as a failure


class CheckFailed(Exception):
    """Raised by a check: the device broke the rule the check holds it to."""


class CheckSkipped(Exception):
    """Raised by a check: the rule does not apply to this device (the message says why)."""


def expect(condition: object, message: str) -> None:
    """Fail the running check with ``message`` unless ``condition`` holds."""
    if not condition:
        raise CheckFailed(message)


@dataclass(frozen=True)
class CheckResult:
    name: str  # dotted, area first: "config.limits.width"
    area: str
    outcome: Outcome
    detail: str  # what was observed (PASS), what broke (FAIL), why not applicable (SKIP)
    duration_s: float

    @property
    def failed(self) -> bool:
        return self.outcome in (Outcome.FAIL, Outcome.ERROR)


@dataclass
class SuiteResult:
    url: str
    device: dict[str, object] = field(default_factory=dict)  # INFO as read at the start
    results: list[CheckResult] = field(default_factory=list)
    duration_s: float = 0.0

    def count(self, outcome: Outcome) -> int:
        return sum(r.outcome is outcome for r in self.results)

    @property
    def passed(self) -> bool:
        """True when every applicable check passed (skips do not count against the device)."""
        return bool(self.results) and not any(r.failed for r in self.results)
