"""pixel_rays against OpenCV's distortion model (cv2 is the oracle)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from stereocam.device_sim.calibration.rays import pixel_rays, project_points
from stereocam.device_sim.calibration.truth import true_calibration


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rays_reproject_to_pixel_centres(seed: int) -> None:
    calib = true_calibration(seed, (320, 240))
    K, D = calib.K_left, calib.D_left
    rays = pixel_rays(K, D, 320, 240)
    assert rays.shape == (240, 320, 3) and rays.dtype == np.float32
    assert np.all(rays[..., 2] == 1.0)
    proj, _ = cv2.projectPoints(rays.reshape(-1, 3).astype(np.float64), np.zeros(3), np.zeros(3), K, D)
    v, u = np.mgrid[0:240, 0:320]
    err = np.abs(proj.reshape(240, 320, 2) - np.dstack([u, v]))
    assert err.max() < 1e-3  # float32 ray storage dominates


def test_rays_match_cv2_undistort_points() -> None:
    calib = true_calibration(5, (640, 480))
    K, D = calib.K_right, calib.D_right
    rays = pixel_rays(K, D, 640, 480)
    v, u = np.mgrid[0:480:7, 0:640:7]
    pts = np.dstack([u, v]).reshape(-1, 1, 2).astype(np.float64)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    ref = cv2.undistortPoints(pts, K, D, R=None, P=None, criteria=crit).reshape(v.shape + (2,))
    ours = rays[::7, ::7, :2]
    assert np.abs(ours - ref).max() * K[0, 0] < 1e-3  # in pixels


def test_supersampled_rays_sit_at_subpixel_centres() -> None:
    calib = true_calibration(1, (64, 48))
    rays = pixel_rays(calib.K_left, calib.D_left, 64, 48, supersample=2)
    assert rays.shape == (96, 128, 3)
    proj, _ = cv2.projectPoints(rays[3, 5].astype(np.float64).reshape(1, 3), np.zeros(3), np.zeros(3),
                                calib.K_left, calib.D_left)
    np.testing.assert_allclose(proj.ravel(), [2 + 1.5 / 2 - 0.5, 1 + 1.5 / 2 - 0.5], atol=1e-3)


def test_rays_reject_bad_arguments() -> None:
    with pytest.raises(ValueError, match="5 coefficients"):
        pixel_rays(np.eye(3), np.zeros(4), 10, 10)
    with pytest.raises(ValueError, match="ray grid"):
        pixel_rays(np.eye(3), np.zeros(5), 0, 10)


def test_project_points_matches_cv2() -> None:
    calib = true_calibration(4)
    pts = np.random.default_rng(1).uniform([-0.5, -0.4, 0.5], [0.5, 0.4, 2.0], (100, 3))
    ref, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), calib.K_right, calib.D_right)
    np.testing.assert_allclose(project_points(calib.K_right, calib.D_right, pts), ref.reshape(-1, 2), atol=1e-9)
