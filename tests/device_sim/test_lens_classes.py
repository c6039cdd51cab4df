"""Simulated wide-angle and fisheye units (device_sim/rig/lens.py): chosen by URL, rendered through
their true lenses, and rectified on board to rows that agree."""
from __future__ import annotations

import numpy as np
import pytest

from stereocam.camera import Camera
from stereocam.device_sim.calibration.board import StereoBoardRenderer, board_poses
from stereocam.device_sim.calibration.rays import lens_project, lens_rays
from stereocam.device_sim.calibration.rectify import rectification_maps
from stereocam.device_sim.links.inprocess import open_transport, reopen_url
from stereocam.device_sim.rig.lens import LensClass, lens_calibration
from stereocam.device_sim.rig.sensor import BOARD
from stereocam.protocol.errors import ConfigError
from stereocam.tools.calibration.boards import detect_all

LENSES = {"wide": "rational_polynomial", "fisheye": "equidistant"}


def test_the_url_chooses_the_lens_class_and_the_factory_record_holds_its_truth() -> None:
    transport = open_transport("sim://?seed=3&lens=fisheye", 2.0)
    with Camera(transport, timeout=2.0) as cam:
        sim = transport.sim
        assert sim.lens == LensClass.FISHEYE and sim.true_calibration().lens_model == "equidistant"
        stored = cam.read_calibration("factory")
        assert stored is not None and stored.body == sim.true_calibration().to_bytes()
        assert cam.info().calibration_id == stored.calibration_id  # accepted at boot: in force
    assert reopen_url("sim://?seed=3&lens=wide", "SN") == "sim://?seed=3&serial=SN&lens=wide"
    with pytest.raises(ConfigError, match="unknown lens class 'zoom'; known: standard, wide, fisheye"):
        open_transport("sim://?lens=zoom", 2.0)


@pytest.mark.parametrize("lens", LENSES)
def test_rays_invert_the_lens_over_the_whole_image(lens: str) -> None:
    c = lens_calibration(2, lens, (64, 48))
    assert c.lens_model == LENSES[lens]
    rays = lens_rays(c.K_right, c.D_right, c.lens_model, 64, 48).reshape(-1, 3).astype(np.float64)
    v, u = np.mgrid[0:48, 0:64]
    np.testing.assert_allclose(lens_project(c.K_right, c.D_right, c.lens_model, rays),
                               np.column_stack([u.ravel(), v.ravel()]), atol=1e-4)
    if lens == "fisheye":  # a 180 degree lens: the middle of the left and right edges look sideways
        side = rays[24 * 64] / np.linalg.norm(rays[24 * 64])
        assert abs(np.degrees(np.arccos(side[2])) - 90) < 6


@pytest.mark.parametrize("lens", LENSES)
def test_board_corners_land_where_the_lens_puts_them_and_rectify_to_equal_rows(lens: str) -> None:
    """The rig renders through its true lens (detected corners = the lens projection of the board's
    corners), and on-board rectification with that truth leaves < 0.1 px of vertical disparity."""
    c = lens_calibration(4, lens, (640, 480))
    renderer = StereoBoardRenderer(c, BOARD)
    maps = rectification_maps(c)
    rng = np.random.default_rng(1)
    raw_err, dy = [], []
    for pose in board_poses(4, 5, BOARD, c, distance_m=LensClass(lens).board_distance_m):
        left, right = renderer.render(pose, rng)
        rl, rr = maps.rectify(left, right)
        found = [detect_all(img, BOARD) for img in (left, rl, rr)]
        if not all(found):  # the board out of the rectified view, or too oblique for the detectors
            continue
        raw, cl, cr = (next(iter(d.values())).image_points for d in found)
        truth = lens_project(c.K_left, c.D_left, c.lens_model, BOARD.object_points() @ pose.R.T + pose.t)
        if np.linalg.norm(raw[0] - truth[0]) > np.linalg.norm(raw[0] - truth[-1]):
            raw = raw[::-1]
        raw_err.append(np.linalg.norm(raw - truth, axis=1))
        if np.dot(cl[-1] - cl[0], cr[-1] - cr[0]) < 0:
            cr = cr[::-1]
        dy.append(cl[:, 1] - cr[:, 1])
    assert len(dy) >= 3
    assert np.sqrt(np.mean(np.concatenate(raw_err) ** 2)) < 0.1
    assert np.sqrt(np.mean(np.concatenate(dy) ** 2)) < 0.1


@pytest.mark.parametrize("lens", ["fisheye", "standard"])
def test_the_rectified_field_of_view_sets_the_focal_length_frames_carry(lens: str) -> None:
    """Device parameter rectified_fov (SPEC §5.1, §12.6 step 3): a fisheye unit's FRAME_BEGIN f is
    (W/2)/tan(fov/2), changed while streaming; the host derives the same geometry (no mismatch).
    A pinhole unit ignores it."""
    transport = open_transport(f"sim://?seed=3&lens={lens}", 2.0)
    with Camera(transport, timeout=2.0) as cam:
        cam.configure(width=320, height=240, num_disparities=16, block_size=5, trigger_mode=1, outputs=4)
        cam.start()
        focal = {}
        for fov in (60, 90):
            cam.configure(rectified_fov=fov)
            cam.trigger()
            f = cam.get_frame(timeout=30)
            assert f.rectified
            focal[fov] = f.geometry.focal_px
        cam.stop()
        assert cam.geometry_mismatches == 0
    if lens == "fisheye":
        for fov, f in focal.items():
            assert f == pytest.approx(160 / np.tan(np.radians(fov) / 2), rel=1e-5)
    else:
        assert focal[60] == focal[90]
