"""Protocol conformance suite: ``stereocam conformance URL`` judges any camera through the wire alone.

No simulator import, no ground truth, no parameter outside protocol/SPEC.md: what a firmware
team's board must do to be driven by this stack. ``run_suite(url)`` returns the results;
``report`` writes them as text, JUnit XML or JSON.
"""
from .results import CheckResult, Outcome, SuiteResult
from .runner import run_suite

__all__ = ["run_suite", "SuiteResult", "CheckResult", "Outcome"]
