"""STEREOCAM_TIME_FACTOR: one factor stretches every real-link budget, and a bad value is refused."""
from __future__ import annotations

import pytest

from stereocam.protocol.errors import ConfigError
from stereocam.tools.conformance.budget import TIME_FACTOR_ENV, budget, time_factor


def test_unset_the_budgets_are_the_specs(monkeypatch):
    monkeypatch.delenv(TIME_FACTOR_ENV, raising=False)
    assert time_factor() == 1.0 and budget(5.0) == 5.0


def test_the_factor_stretches_every_budget(monkeypatch):
    monkeypatch.setenv(TIME_FACTOR_ENV, "2.5")
    assert budget(5.0) == 12.5 and budget(0.2) == pytest.approx(0.5)


@pytest.mark.parametrize("raw", ["fast", "0.5", "0", "-1", "nan"])
def test_a_factor_that_would_not_stretch_is_refused(monkeypatch, raw):
    monkeypatch.setenv(TIME_FACTOR_ENV, raw)
    with pytest.raises(ConfigError, match=TIME_FACTOR_ENV):
        time_factor()
