"""StereoCalibration: validation, JSON and binary round trips, scaling; truth.py's units."""
from __future__ import annotations

import json
import struct

import cv2
import numpy as np
import pytest

from stereocam.protocol.calibration import (
    CalibrationFormatError, CalibrationQuality, StereoCalibration, body_size,
)
from stereocam.device_sim.calibration.truth import true_calibration


@pytest.fixture
def calib() -> StereoCalibration:
    return true_calibration(3)


def test_json_round_trip_with_quality(calib: StereoCalibration) -> None:
    q = CalibrationQuality(rms_left=0.2, rms_stereo=0.3, views_used=20, passed=True, written=False)
    d = json.loads(json.dumps(calib.to_json_dict(q)))
    assert d["image_size"] == [1280, 960]
    assert d["passed"] is True and "rms_right" not in d
    back = StereoCalibration.from_json_dict(d)
    for key in ("K_left", "D_left", "K_right", "D_right", "R", "T"):
        np.testing.assert_array_equal(getattr(back, key), getattr(calib, key))
    assert CalibrationQuality.from_json_dict(d) == q


def test_json_missing_key_names_it(calib: StereoCalibration) -> None:
    d = calib.to_json_dict()
    del d["D_right"]
    with pytest.raises(CalibrationFormatError, match="D_right"):
        StereoCalibration.from_json_dict(d)


def test_bytes_round_trip_and_layout(calib: StereoCalibration) -> None:
    body = calib.to_bytes()
    assert len(body) == body_size() == 250
    assert struct.unpack_from("<5H", body) == (2, 5, 1280, 960, 0)
    assert struct.unpack_from("<d", body, 10)[0] == calib.K_left[0, 0]
    assert struct.unpack_from("<3d", body, 226) == tuple(calib.T)
    back = StereoCalibration.from_bytes(body)
    assert back.to_bytes() == body and back.lens_model == "plumb_bob"
    np.testing.assert_array_equal(back.R, calib.R)


def _other_model(calib: StereoCalibration, model: str, n: int) -> StereoCalibration:
    rng = np.random.default_rng(n)
    return StereoCalibration(calib.image_size, calib.K_left, rng.normal(0, 0.01, n), calib.K_right,
                             rng.normal(0, 0.01, n), calib.R, calib.T, model)


@pytest.mark.parametrize("model, n", [("rational_polynomial", 8), ("equidistant", 4)])
def test_every_lens_model_round_trips(calib: StereoCalibration, model: str, n: int) -> None:
    other = _other_model(calib, model, n)
    body = other.to_bytes()
    assert len(body) == body_size(model) == 170 + 16 * n
    back = StereoCalibration.from_bytes(body)
    assert back.lens_model == model and back.to_bytes() == body
    np.testing.assert_array_equal(back.D_right, other.D_right)
    d = json.loads(json.dumps(other.to_json_dict()))
    assert d["lens_model"] == model and StereoCalibration.from_json_dict(d).to_bytes() == body
    assert other.scaled(640, 480).lens_model == model


def test_version_1_bodies_are_still_read(calib: StereoCalibration) -> None:
    values = [*calib.K_left[[0, 1, 0, 1], [0, 1, 2, 2]], *calib.D_left, *calib.K_right[[0, 1, 0, 1], [0, 1, 2, 2]],
              *calib.D_right, *calib.R.ravel(), *calib.T]
    v1 = struct.pack("<4H30d", 1, 5, 1280, 960, *values)
    assert StereoCalibration.from_bytes(v1).to_bytes() == calib.to_bytes()


@pytest.mark.parametrize("mutate, match", [
    (lambda b: b[:-1], "250 bytes"),
    (lambda b: struct.pack("<H", 3) + b[2:], "version 3"),
    (lambda b: b[:2] + struct.pack("<H", 8) + b[4:], "count 8"),
    (lambda b: b[:8] + struct.pack("<H", 7) + b[10:], "lens model code 7"),
    (lambda b: b[:3], "too short"),
])
def test_bytes_rejects_bad_bodies(calib: StereoCalibration, mutate, match: str) -> None:
    with pytest.raises(CalibrationFormatError, match=match):
        StereoCalibration.from_bytes(mutate(calib.to_bytes()))


def test_validation_names_the_problem(calib: StereoCalibration) -> None:
    K = calib.K_left.copy()
    K[0, 1] = 0.5
    with pytest.raises(CalibrationFormatError, match="K_left"):
        StereoCalibration(calib.image_size, K, calib.D_left, calib.K_right, calib.D_right, calib.R, calib.T)
    with pytest.raises(CalibrationFormatError, match="D_right"):
        StereoCalibration(calib.image_size, calib.K_left, calib.D_left, calib.K_right, [0.1], calib.R, calib.T)
    with pytest.raises(CalibrationFormatError, match="unknown lens model"):
        StereoCalibration(calib.image_size, calib.K_left, calib.D_left, calib.K_right, calib.D_right, calib.R,
                          calib.T, "kannala")
    with pytest.raises(CalibrationFormatError, match="rotation"):
        StereoCalibration(calib.image_size, calib.K_left, calib.D_left, calib.K_right, calib.D_right,
                          2 * calib.R, calib.T)
    with pytest.raises(CalibrationFormatError, match="non-finite"):
        StereoCalibration(calib.image_size, calib.K_left, calib.D_left, calib.K_right, calib.D_right,
                          calib.R, [np.nan, 0, 0])


def test_scaled_matches_binned_projection(calib: StereoCalibration) -> None:
    """Projecting into the full frame then 2x2-binning = projecting with the scaled calibration."""
    half = calib.scaled(640, 480)
    assert half.baseline_m == calib.baseline_m
    pts = np.random.default_rng(0).uniform([-0.3, -0.2, 0.8], [0.3, 0.2, 2.0], (50, 3))
    full, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), calib.K_left, calib.D_left)
    small, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), half.K_left, half.D_left)
    np.testing.assert_allclose((full + 0.5) / 2 - 0.5, small, atol=1e-9)


def test_truth_is_reproducible_and_plausible() -> None:
    a, b, c = true_calibration(7), true_calibration(7), true_calibration(8)
    assert a.to_bytes() == b.to_bytes() != c.to_bytes()
    for seed in range(50):
        t = true_calibration(seed)
        for K, D in ((t.K_left, t.D_left), (t.K_right, t.D_right)):
            assert abs(K[0, 0] / 960 - 1) <= 0.031 and K[0, 0] != K[1, 1]
            assert abs(K[1, 1] / K[0, 0] - 1) <= 0.0031
            assert abs(K[0, 2] - 639.5) <= 0.02 * 1280 and abs(K[1, 2] - 479.5) <= 0.02 * 960
            assert -0.1 <= D[0] <= 0.05 and np.all(np.abs(D[2:4]) <= 1.5e-3)
        assert 0.06 <= t.baseline_m <= 0.12 and t.T[0] < 0
        angle = np.degrees(np.linalg.norm(cv2.Rodrigues(t.R)[0]))
        assert 0 < angle < 1.0
    small = true_calibration(7, (640, 480))
    assert abs(small.K_left[0, 0] / 480 - 1) <= 0.031
