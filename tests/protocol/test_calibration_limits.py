"""protocol/calibration_limits.py: real heads pass, impossible ones are named (SPEC §12.3)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from stereocam.device_sim.calibration.truth import true_calibration
from stereocam.protocol.calibration_limits import (CalibrationImplausible, PlausibilityLimits,
                                                   check_plausible)


@pytest.mark.parametrize("seed", range(12))
def test_every_simulated_unit_is_plausible(seed) -> None:
    check_plausible(true_calibration(seed), PlausibilityLimits(sensor_size=(1280, 960)))


@pytest.mark.parametrize("T, field", [([0, 0, 0], "T"), ([-1e300, 0, 0], "T"), ([-3.0, 0, 0], "T")])
def test_baseline_outside_the_rig(T, field) -> None:
    calib = dataclasses.replace(true_calibration(1), T=np.array(T, float))
    with pytest.raises(CalibrationImplausible) as err:
        check_plausible(calib)
    assert err.value.field == field and "baseline" in str(err.value)


def test_limits_are_configurable() -> None:
    calib = dataclasses.replace(true_calibration(2), T=np.array([-0.5, 0.0, 0.0]))
    check_plausible(calib)  # 50 cm is a real rail
    with pytest.raises(CalibrationImplausible, match="baseline"):
        check_plausible(calib, PlausibilityLimits(baseline_m=(0.05, 0.2)))  # not on this unit's rig


def test_sensor_format() -> None:
    with pytest.raises(CalibrationImplausible, match="sensor"):
        check_plausible(true_calibration(3, sensor_size=(2560, 1920)), PlausibilityLimits(sensor_size=(1280, 960)))
    check_plausible(true_calibration(3).scaled(320, 240), PlausibilityLimits(sensor_size=(1280, 960)))
