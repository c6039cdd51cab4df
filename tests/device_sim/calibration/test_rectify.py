"""On-board rectification against OpenCV (the oracle) and on rendered board pairs."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from stereocam.stereo.calibration_board import BoardSpec
from stereocam.device_sim.calibration.board import StereoBoardRenderer, board_poses
from stereocam.protocol.calibration import StereoCalibration
from stereocam.device_sim.calibration.rectify import rectification_maps, remap_bilinear, undistort_rectify_map
from stereocam.device_sim.calibration.truth import true_calibration
from stereocam.protocol.rectification import (EQUIDISTANT_FOV_DEG, _log_rotation, rectified_to_raw, rodrigues,
                                               stereo_rectify, undistort_points)
from stereocam.tools.calibration.boards import detect_all


def cv_rectify(c: StereoCalibration):
    return cv2.stereoRectify(c.K_left, c.D_left, c.K_right, c.D_right, c.image_size, c.R, c.T.reshape(3, 1),
                             flags=cv2.CALIB_ZERO_DISPARITY, alpha=0)[:5]


@pytest.mark.parametrize("seed", range(6))
def test_geometry_matches_cv2_stereo_rectify(seed: int) -> None:
    c = true_calibration(seed, (640, 480))
    g = stereo_rectify(c)
    R1, R2, P1, P2, Q = cv_rectify(c)
    np.testing.assert_allclose(g.R1, R1, atol=1e-12)
    np.testing.assert_allclose(g.R2, R2, atol=1e-12)
    np.testing.assert_allclose(g.P1, P1, atol=1e-4)
    np.testing.assert_allclose(g.P2, P2, atol=1e-4 * 0.12)
    np.testing.assert_allclose(g.Q, Q, atol=1e-4)
    assert g.baseline_m == pytest.approx(c.baseline_m, rel=1e-12)
    assert (g.focal_px, g.cx, g.cy) == (g.P2[0, 0], g.P2[0, 2], g.P2[1, 2])  # zero disparity
    # Q maps (x, y, d) to the 3-D point: Z = f·B/d
    X = g.Q @ np.array([g.cx + 10, g.cy, 20.0, 1.0])
    assert X[2] / X[3] == pytest.approx(g.focal_px * g.baseline_m / 20.0)


def test_maps_match_cv2() -> None:
    c = true_calibration(3, (640, 480))
    m = rectification_maps(c)
    R1, R2, P1, P2, _ = cv_rectify(c)
    for (K, D, R, P), ours in (((c.K_left, c.D_left, R1, P1), (m.left_x, m.left_y)),
                               ((c.K_right, c.D_right, R2, P2), (m.right_x, m.right_y))):
        ref = cv2.initUndistortRectifyMap(K, D, R, P, c.image_size, cv2.CV_32FC1)
        assert ours[0].dtype == np.float32 and ours[0].shape == (480, 640)
        assert max(np.abs(ours[0] - ref[0]).max(), np.abs(ours[1] - ref[1]).max()) < 2e-3
    exact = cv2.initUndistortRectifyMap(c.K_left, c.D_left, m.geometry.R1, m.geometry.P1, c.image_size, cv2.CV_32FC1)
    assert np.abs(m.left_x - exact[0]).max() < 1e-3 and np.abs(m.left_y - exact[1]).max() < 1e-3
    # alpha = 0: every rectified pixel samples inside the raw image (up to the 9-point border sampling)
    for mx, my in ((m.left_x, m.left_y), (m.right_x, m.right_y)):
        assert mx.min() > -0.5 and mx.max() < 639.5 and my.min() > -0.5 and my.max() < 479.5


def test_remap_matches_cv2_within_one_dn() -> None:
    rng = np.random.default_rng(0)
    img = cv2.GaussianBlur(rng.integers(0, 256, (480, 640), dtype=np.uint8), (0, 0), 1.0)
    c = true_calibration(4, (640, 480))
    m = rectification_maps(c)
    for mx, my in ((m.left_x, m.left_y),
                   (rng.uniform(-3, 643, (100, 200)).astype(np.float32),
                    rng.uniform(-3, 483, (100, 200)).astype(np.float32))):
        ours = remap_bilinear(img, mx, my).astype(int)
        ref = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0).astype(int)
        assert np.abs(ours - ref).max() <= 1
        assert np.mean(ours != ref) < 0.01


def test_remap_edges_and_validation() -> None:
    img = np.full((4, 5), 200, np.uint8)
    mx = np.array([[0.0, 4.0, 4.5, -0.5, -1.0, 2.0]], np.float32)
    my = np.array([[0.0, 3.0, 1.0, 1.0, 1.0, 3.5]], np.float32)
    assert remap_bilinear(img, mx, my).tolist() == [[200, 200, 100, 100, 0, 100]]
    with pytest.raises(ValueError, match="uint8"):
        remap_bilinear(img.astype(np.float32), mx, my)
    with pytest.raises(ValueError, match="float32"):
        remap_bilinear(img, mx.astype(np.float64), my)


def test_rectified_board_rows_align() -> None:
    """Render a board through the true head, rectify on board: corner rows agree to < 0.1 px."""
    c = true_calibration(6, (640, 480))
    board = BoardSpec(9, 6, 0.03)
    renderer = StereoBoardRenderer(c, board, supersample=1)
    m = rectification_maps(c)
    rng = np.random.default_rng(2)
    dy, disparity_depth = [], []
    for pose in board_poses(6, 3, board, c, distance_m=(0.4, 0.8)):
        left, right = m.rectify(*renderer.render(pose, rng))
        cl, cr = (detect_all(img, board)["classic"].image_points for img in (left, right))
        if np.dot(cl[-1] - cl[0], cr[-1] - cr[0]) < 0:
            cr = cr[::-1]
        dy.append(cl[:, 1] - cr[:, 1])
        z_true = (board.object_points() @ pose.R.T + pose.t)[:, 2]
        z = m.geometry.focal_px * m.geometry.baseline_m / (cl[:, 0] - cr[:, 0])
        disparity_depth.append(z / z_true - 1)
    assert np.sqrt(np.mean(np.concatenate(dy) ** 2)) < 0.1
    assert np.abs(np.concatenate(disparity_depth)).max() < 0.01


def test_vertical_head_is_rejected() -> None:
    c = true_calibration(0, (640, 480))
    vertical = StereoCalibration(c.image_size, c.K_left, c.D_left, c.K_right, c.D_right, np.eye(3), [0, -0.1, 0])
    with pytest.raises(ValueError, match="horizontal"):
        stereo_rectify(vertical)


@pytest.mark.parametrize("rvec", [[0.0, 0.0, 0.0], [1e-9, 0, 0], [0.01, -0.02, 0.005], [0.5, 1.0, -2.0],
                                  [np.pi, 0.0, 0.0], [0.0, np.pi * 0.6, np.pi * 0.8]])
def test_log_rotation_inverts_rodrigues(rvec) -> None:
    R = rodrigues(np.array(rvec))
    np.testing.assert_allclose(rodrigues(_log_rotation(R)), R, atol=1e-9)


def test_undistort_rectify_map_identity() -> None:
    K = np.array([[500.0, 0, 10.0], [0, 500.0, 8.0], [0, 0, 1]])
    mx, my = undistort_rectify_map(K, np.zeros(5), np.eye(3), np.hstack([K, np.zeros((3, 1))]), (20, 16))
    v, u = np.mgrid[0:16, 0:20]
    np.testing.assert_allclose(mx, u, atol=1e-4)
    np.testing.assert_allclose(my, v, atol=1e-4)


@pytest.mark.parametrize("model, D", [
    ("rational_polynomial", [-0.2, 0.05, 1e-4, -2e-4, 0.01, 0.1, 0.02, 0.005]),
    ("equidistant", [0.05, -0.01, 0.002, -0.0005]),
])
def test_maps_of_every_lens_model_match_opencv(model: str, D: list[float]) -> None:
    """On-board maps for the rational and fisheye models equal OpenCV's own map builders."""
    c = true_calibration(4, (320, 240))
    c = StereoCalibration(c.image_size, c.K_left, D, c.K_right, D, c.R, c.T, model)
    m = rectification_maps(c)
    g = m.geometry
    if model == "equidistant":
        mx, my = cv2.fisheye.initUndistortRectifyMap(c.K_left, np.array(D), g.R1, g.P1, c.image_size, cv2.CV_32FC1)
    else:
        mx, my = cv2.initUndistortRectifyMap(c.K_left, np.array(D), g.R1, g.P1, c.image_size, cv2.CV_32FC1)
    np.testing.assert_allclose(m.left_x, mx, atol=2e-3)
    np.testing.assert_allclose(m.left_y, my, atol=2e-3)
    # the geometry's undistortion inverts the lens: rectified corners of a pixel grid are consistent
    pts = np.array([[10.0, 12.0], [160.0, 120.0], [300.0, 220.0]])
    norm = undistort_points(c.K_left, np.array(D), pts, 100, model)
    if model == "equidistant":
        back = cv2.fisheye.distortPoints(norm.reshape(-1, 1, 2), c.K_left, np.array(D)).reshape(-1, 2)
    else:
        back = cv2.projectPoints(np.column_stack([norm, np.ones(3)]), np.zeros(3), np.zeros(3), c.K_left,
                                 np.array(D))[0].reshape(-1, 2)
    np.testing.assert_allclose(back, pts, atol=1e-6)


@pytest.mark.parametrize("fov", [60, 150, 180, 190])
def test_equidistant_view_has_the_stated_field_and_only_valid_pixels(fov: int) -> None:
    """SPEC §12.6 step 3 for fisheye lenses: the principal point at the image centre, f from the output
    field of view (120° by default) unless a narrower lens needs a longer focal; every pixel sees the sensor."""
    from stereocam.device_sim.calibration import lens_views as synth
    c = synth.rig("equidistant", fov, (320, 240)).truth()
    m = rectification_maps(c)
    g = m.geometry
    assert (g.cx, g.cy) == (159.5, 119.5)
    f_fov = 160 / np.tan(np.radians(EQUIDISTANT_FOV_DEG) / 2)
    assert g.focal_px >= f_fov * (1 - 1e-12)
    if fov in (150, 180):
        assert g.focal_px == pytest.approx(f_fov, rel=1e-12)
    if fov == 60:  # the lens sees less than 120°: the view narrows to what it sees
        assert g.focal_px > 1.3 * f_fov
    assert stereo_rectify(c, fov_deg=90).focal_px >= 160 * (1 - 1e-12)
    for mx, my in ((m.left_x, m.left_y), (m.right_x, m.right_y)):
        assert mx.min() > -0.5 and mx.max() < 319.5 and my.min() > -0.5 and my.max() < 239.5
    np.testing.assert_allclose(rectified_to_raw(c.K_left, c.D_left, c.lens_model, g.R1, g.P1,
                                                np.array([[5.0, 7.0], [300.0, 200.0]])),
                               [[m.left_x[7, 5], m.left_y[7, 5]], [m.left_x[200, 300], m.left_y[200, 300]]], atol=1e-3)
    with pytest.raises(ValueError, match="field of view"):
        stereo_rectify(c, fov_deg=180)
