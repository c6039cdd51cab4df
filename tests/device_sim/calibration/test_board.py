"""Board renderer: poses are reproducible and visible; rendered corners sit where the truth says."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from stereocam.stereo.calibration_board import BoardSpec
from stereocam.device_sim.calibration.board import StereoBoardRenderer, board_poses, render_board_view
from stereocam.device_sim.calibration.rays import pixel_rays, project_points
from stereocam.device_sim.calibration.truth import true_calibration

CALIB = true_calibration(2, (640, 480))
BOARD = BoardSpec(9, 6, 0.03)


def test_poses_reproducible_and_in_range() -> None:
    a = list(board_poses(4, 12, BOARD, CALIB))
    b = list(board_poses(4, 12, BOARD, CALIB))
    assert all(np.array_equal(p.R, q.R) and np.array_equal(p.t, q.t) for p, q in zip(a, b))
    centre = np.array([4, 2.5, 0]) * 0.03
    for p in a:
        assert 0.4 <= (p.R @ centre + p.t)[2] <= 1.5
        tilt = np.degrees(np.arccos(abs(p.R[2, 2])))
        assert tilt <= 40.01
        for K, D, pts in ((CALIB.K_left, CALIB.D_left, BOARD.outline() @ p.R.T + p.t),
                          (CALIB.K_right, CALIB.D_right, (BOARD.outline() @ p.R.T + p.t) @ CALIB.R.T + CALIB.T)):
            uv = project_points(K, D, pts)
            assert np.all(uv >= 0) and np.all(uv < [640, 480])
    xs = [(p.R @ centre + p.t)[0] / (p.R @ centre + p.t)[2] for p in a]
    assert max(xs) - min(xs) > 0.3  # spread across the field of view


def test_impossible_board_is_an_error() -> None:
    with pytest.raises(ValueError, match="does not fit"):
        list(board_poses(0, 1, BoardSpec(9, 6, 0.2), CALIB, distance_m=(0.4, 0.5)))
    with pytest.raises(ValueError, match="bad board"):
        BoardSpec(1, 6, 0.03)


def test_rendered_corners_match_projection() -> None:
    renderer = StereoBoardRenderer(CALIB, BOARD, supersample=4)
    rng = np.random.default_rng(0)
    errors = []
    for pose in board_poses(1, 4, BOARD, CALIB, distance_m=(0.35, 0.8)):
        left, right = renderer.render(pose, rng)
        assert left.dtype == np.uint8 and left.shape == (480, 640)
        cam_pts = BOARD.object_points() @ pose.R.T + pose.t
        for img, K, D, pts in ((left, CALIB.K_left, CALIB.D_left, cam_pts),
                               (right, CALIB.K_right, CALIB.D_right, cam_pts @ CALIB.R.T + CALIB.T)):
            found, corners = cv2.findChessboardCorners(img, (9, 6))
            assert found
            corners = cv2.cornerSubPix(img, corners, (5, 5), (-1, -1),
                                       (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4))
            truth = project_points(K, D, pts)
            c = corners.reshape(-1, 2)
            if np.linalg.norm(c[0] - truth[0]) > np.linalg.norm(c[-1] - truth[0]):
                c = c[::-1]  # OpenCV may start from the opposite corner
            errors.append(c - truth)
    e = np.concatenate(errors)
    assert np.sqrt((e ** 2).sum(axis=1).mean()) < 0.08  # cornerSubPix's own floor is ~0.05 px
    assert np.all(np.abs(e.mean(axis=0)) < 0.02)


def test_noise_free_render_is_deterministic_and_antialiased() -> None:
    renderer = StereoBoardRenderer(CALIB, BOARD, supersample=1)
    pose = next(board_poses(3, 1, BOARD, CALIB))
    a, _ = renderer.render(pose, noise_sigma=0.0)
    b, _ = renderer.render(pose, noise_sigma=0.0)
    assert np.array_equal(a, b)
    assert a.min() == 30 and a.max() == 220
    levels = np.isin(a, [30, 110, 220])
    assert 0.8 < levels.mean() < 1.0  # edges carry intermediate, area-weighted values


def test_axis_aligned_edge_is_area_weighted() -> None:
    """A fronto-parallel board: the pixel straddling a vertical edge gets the covered fraction."""
    K = np.array([[800.0, 0, 319.5], [0, 800.0, 239.5], [0, 0, 1]])
    rays = pixel_rays(K, np.zeros(5), 640, 480)
    t = np.array([-0.1 + 0.3 / 800 * 0.6, -0.07, 0.6])        # first corner at u = 186.8
    img = render_board_view(rays, np.eye(3), t, BOARD, noise_sigma=0, black=0, white=200)
    u, v = project_points(K, np.zeros(5), t.reshape(1, 3))[0]
    assert abs(u - (319.5 - 0.1 / 0.6 * 800 + 0.3)) < 1e-9
    col, row = int(round(u)), int(round(v)) - 3           # above the corner: black left, white right
    assert img[row, col - 1] == 0 and img[row, col + 1] == 200
    assert img[row, col] == round(200 * (col + 0.5 - u))
