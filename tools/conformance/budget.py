"""Time budgets on a real link, and the one factor that stretches them on a slow or busy host.

A budget is how long the suite waits for something the device must deliver (a whole capture, a
reply). On a loaded host the simulator (or the host's own reader) can be late for reasons that
are not the device's fault, so every budget is multiplied by ``STEREOCAM_TIME_FACTOR`` (default
1: the figures of the SPEC; the test suite sets a larger default, tests/conftest.py).
"""
from __future__ import annotations

import os

from stereocam.protocol.errors import ConfigError

TIME_FACTOR_ENV = "STEREOCAM_TIME_FACTOR"


def time_factor() -> float:
    """The factor from the environment (1.0 when unset); ConfigError unless a number >= 1."""
    raw = os.environ.get(TIME_FACTOR_ENV, "").strip()
    if not raw:
        return 1.0
    try:
        factor = float(raw)
    except ValueError:
        raise ConfigError(f"{TIME_FACTOR_ENV}={raw!r} is not a number") from None
    if not factor >= 1.0:
        raise ConfigError(f"{TIME_FACTOR_ENV}={raw!r}: a budget is only ever stretched (>= 1)")
    return factor


def budget(seconds: float) -> float:
    """``seconds`` as a deadline on this host: stretched by the time factor."""
    return seconds * time_factor()
