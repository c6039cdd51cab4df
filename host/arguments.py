"""Checks on what a caller passes in: timeouts and integer parameters, with errors naming the argument."""
from __future__ import annotations

import decimal
import math
import numbers
import unicodedata
from collections.abc import Mapping

import numpy as np

from stereocam.protocol.errors import ConfigError
from stereocam.protocol.params import BY_NAME, INT32_MAX, INT32_MIN



LONGEST_WAIT = 1e9  # s (31 years): longer waits are cut to this (the OS's timed waits end near 2.9e11 s)
MAX_RETRIES = 100  # resends of one request: more only hides a dead link


def timeout_arg(value: object, name: str = "timeout", minimum: float = 0.0) -> float:
    """``value`` as float seconds: a finite real number of at least ``minimum`` (bool refused), else
    ConfigError; a wait longer than 31 years is cut to that."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ConfigError(f"{name} must be a number of seconds, got {value!r}")
    seconds = float(value)
    if not math.isfinite(seconds) or seconds < minimum:
        raise ConfigError(f"{name} must be finite and at least {minimum:g} s, got {value!r}")
    return min(seconds, LONGEST_WAIT)


def request_timeout_arg(value: object, name: str = "timeout") -> float:
    """A request's reply timeout: ``timeout_arg`` that must also be > 0 (0 would mean no wait at all)."""
    seconds = timeout_arg(value, name)
    if seconds <= 0:
        raise ConfigError(f"{name} must be more than 0 s (the wait for each reply), got {value!r}")
    return seconds


def retries_arg(value: object, name: str = "retries") -> int:
    """A request's resend count: an integer in 0..MAX_RETRIES."""
    count = count_arg(value, name)
    if count > MAX_RETRIES:
        raise ConfigError(f"{name} must be at most {MAX_RETRIES}, got {value!r}")
    return count


def url_arg(value: object) -> str:
    """A camera URL: a non-empty str without control characters, else ConfigError naming it."""
    if not isinstance(value, str) or not value:
        raise ConfigError(f"a camera URL must be a non-empty string, got {value!r}")
    bad = next((c for c in value if unicodedata.category(c) == "Cc"), None)
    if bad is not None:
        raise ConfigError(f"camera URL {value!r} contains a control character ({bad!r})")
    return value


def count_arg(value: object, name: str, minimum: int = 0) -> int:
    """``value`` as an int of at least ``minimum`` (numpy integers too; bool and floats refused)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        raise ConfigError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def flag_arg(value: object, name: str) -> bool:
    """``value`` as a bool: True or False (numpy's too), nothing else."""
    if not isinstance(value, (bool, np.bool_)):
        raise ConfigError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def int32_arg(value: object, name: str) -> int:
    """``value`` as an int32: any integral number (numpy's included) or an integer-valued float,
    Fraction or Decimal."""
    if isinstance(value, bool):
        raise ConfigError(f"{name} must be an integer, got {value!r}")
    if isinstance(value, numbers.Integral):
        number = int(value)
    elif isinstance(value, decimal.Decimal) and value.is_finite() and value == value.to_integral_value():
        number = int(value)  # not a numbers.Real; float() of a signalling NaN raises
    elif isinstance(value, numbers.Real) and float(value).is_integer():
        number = int(float(value))
    else:
        raise ConfigError(f"{name} must be an integer, got {value!r}")
    if not INT32_MIN <= number <= INT32_MAX:
        raise ConfigError(f"{name}={number} does not fit the protocol's int32 ({INT32_MIN}..{INT32_MAX})")
    return number


def config_update(params: Mapping[str, object]) -> dict[int, int]:
    """Parameters by name as a SET_CONFIG update (wire id → int32); ConfigError for an unknown name
    or a value that is not an integer fitting the wire."""
    update = {}
    for name, value in params.items():
        p = BY_NAME.get(name)
        if p is None:
            raise ConfigError(f"unknown parameter {name!r}; known: {', '.join(BY_NAME)}")
        update[p.pid] = int32_arg(value, name)
    return update
