"""Waiting on a condition with a deadline, instead of sleeping a fixed time and then asserting."""
from __future__ import annotations

import time
from typing import Callable, TypeVar

from stereocam.tools.conformance.budget import budget

T = TypeVar("T")
POLL_S = 0.005


def wait_until(predicate: Callable[[], T], timeout: float = 5.0, what: str = "") -> T:
    """The first truthy value of ``predicate()``, polled until ``timeout`` seconds (stretched by
    STEREOCAM_TIME_FACTOR) have passed; a test failure naming ``what`` if it never comes."""
    deadline = time.monotonic() + budget(timeout)
    while not (value := predicate()):
        assert time.monotonic() < deadline, f"not within {budget(timeout):.3g} s: {what or predicate}"
        time.sleep(POLL_S)
    return value


def stays(predicate: Callable[[], object], seconds: float) -> bool:
    """Whether ``predicate()`` holds throughout ``seconds`` (for what must not happen: a negative
    can only be watched for a while)."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if not predicate():
            return False
        time.sleep(POLL_S)
    return bool(predicate())
