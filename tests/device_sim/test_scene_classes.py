"""The scene classes: exact truth from the rig's geometry (slanted plane against its analytic
disparity, the occlusion mask against the analytic shadow of a panel), their photometry, and the
simulator serving them by name."""
from __future__ import annotations

import numpy as np
import pytest

from stereocam.device_sim.calibration.truth import true_calibration
from stereocam.device_sim.rig import render
from stereocam.device_sim.rig.photometry import PLAIN, Photometry
from stereocam.device_sim.rig.scene import Scene
from stereocam.device_sim.rig.scene_classes import CLASSES, DISPARITIES_WIDTH
from stereocam.device_sim.rig.sensor import LIGHT, SensorRig
from stereocam.device_sim.rig.shapes import cylinder, rect
from stereocam.device_sim.rig.stereo_pair import ideal_geometry, render_pair, render_primitives, scene_class

W, H = 160, 120


def pixel_rays(width: int, height: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    g = ideal_geometry(width, height)
    rays = g.rays().astype(np.float64)
    return rays[..., 0], rays[..., 1], g.focal_px * g.baseline_m


def test_slanted_plane_truth_is_the_analytic_plane():
    prims = CLASSES["slanted"].build(0.0, seed=0)
    board = prims[2]  # the big slanted board
    c, n = board[render.CX:render.CZ + 1], board[render.NX:render.NZ + 1]
    a1, a2 = board[render.A1X:render.A1Z + 1], board[render.A2X:render.A2Z + 1]
    rx, ry, fb = pixel_rays(W, H)
    z = (n @ c) / (n[0] * rx + n[1] * ry + n[2])  # ray (rx, ry, 1) meets the plane at depth z
    hit = np.stack([rx * z, ry * z, z], axis=-1) - c
    on_board = (np.abs(hit @ a1) < board[render.H1] - 1e-3) & (np.abs(hit @ a2) < board[render.H2] - 1e-3)
    assert on_board.mean() > 0.15
    truth = render_pair("slanted", W, H, seed=0).disparity
    assert np.allclose(truth[on_board], (fb / z)[on_board], rtol=1e-5)
    assert np.ptp((fb / z)[on_board]) > 3  # really slanted: disparity changes across it


def test_cylinder_truth_is_the_analytic_tube():
    xc, zc, r, h = 0.1, 1.5, 0.3, 0.4
    prims = np.array([cylinder((xc, 0.0, zc), (0, 1, 0), r, h), rect((0, 0, 4.0), (1, 0, 0), (0, 1, 0), 50.0, 50.0)])
    rx, ry, fb = pixel_rays(W, H)
    a, b, c = rx ** 2 + 1, rx * xc + zc, xc ** 2 + zc ** 2 - r ** 2  # (rx z - xc)^2 + (z - zc)^2 = r^2
    disc = b ** 2 - a * c
    z = (b - np.sqrt(np.maximum(disc, 0))) / a
    on_tube = (disc > 1e-4) & (np.abs(ry * z) < h - 1e-3)
    assert on_tube.mean() > 0.1
    pair = render_primitives("tube", [prims], prims, PLAIN, ideal_geometry(W, H), seed=0)
    assert np.allclose(pair.disparity[on_tube], (fb / z)[on_tube], rtol=1e-5)
    assert np.allclose(pair.disparity[~on_tube & (np.abs(ry) > 0.5)], fb / 4.0, rtol=1e-5)  # wall above and below


def test_layered_render_of_cylinders_is_the_full_render():
    rig = SensorRig(5, true_calibration(5))
    rig.set_format(W, H)
    prims = CLASSES["curved"].build(0.0)
    tubes = np.flatnonzero(prims[:, render.KIND] == render.CYLINDER)
    static = np.setdiff1d(np.arange(len(prims)), tubes)
    assert tubes.size == 2
    for eye in (0, 1):
        origin, rot = rig._poses[eye]
        args = (rig.texture, rig.tex_offsets, rig.tex_side, LIGHT)
        full = np.empty((H, W), np.float32)
        render.render_radiance(rig._rays[eye], origin, rot, prims, *args, full, np.empty_like(full))
        base, t, hit = np.empty((H, W), np.float32), np.empty((H, W)), np.empty((H, W), np.int64)
        render.render_layer(rig._rays[eye], origin, rot, prims, static, *args, base, t, hit)
        over = np.empty_like(full)
        render.render_over(rig._rays[eye], rig._cones[eye], origin, rot, prims, tubes, base, t, hit, *args, over)
        assert np.array_equal(over, full)


def test_occlusion_mask_is_the_panels_shadow_in_the_right_view():
    a, z_panel, z_wall = 0.2013, 1.0, 4.0
    prims = np.array([rect((0, 0, z_panel), (1, 0, 0), (0, 1, 0), a, a),
                      rect((0, 0, z_wall), (1, 0, 0), (0, 1, 0), 50.0, 50.0)])
    g = ideal_geometry(W, H)
    pair = render_primitives("panel", [prims], prims, PLAIN, g, seed=1)
    f, b, cx = g.focal_px, g.baseline_m, g.cx
    x = np.arange(W, dtype=np.float64)
    d_wall = f * b / z_wall
    panel_in_right = (cx + f * (-a - b) / z_panel, cx + f * (a - b) / z_panel)
    row = H // 2
    on_panel = np.abs(x - cx) <= f * a / z_panel
    shadow = ~on_panel & (x - d_wall >= panel_in_right[0]) & (x - d_wall <= panel_in_right[1])
    out_of_view = ~on_panel & (x - d_wall < -0.5)
    assert shadow.sum() == pytest.approx(f * b * (1 / z_panel - 1 / z_wall), abs=1)
    assert np.array_equal(pair.occluded[row], shadow | out_of_view)
    assert np.allclose(pair.disparity[row], np.where(on_panel, f * b / z_panel, d_wall), rtol=1e-5)
    above = pair.occluded[0]  # above the panel: only the strip the right camera cannot see
    assert np.array_equal(above, x - d_wall < -0.5) and np.allclose(pair.disparity[0], d_wall, rtol=1e-5)


@pytest.mark.parametrize("name", list(CLASSES))
def test_every_class_has_seeded_truth_within_the_disparity_range(name):
    pair = render_pair(name, W, H, seed=2)
    assert np.isfinite(pair.disparity).all()  # every class fills the view
    assert 0 < np.nanmax(pair.disparity) < CLASSES[name].disparities * W / DISPARITIES_WIDTH  # within its range
    assert 0 < pair.occluded.mean() < 0.3
    assert explained_occlusions(pair.disparity, pair.occluded) > 0.99
    again, other = render_pair(name, W, H, seed=2), render_pair(name, W, H, seed=3)
    assert np.array_equal(again.left, pair.left) and np.array_equal(again.disparity, pair.disparity)
    assert not np.array_equal(other.left, pair.left)


def test_driving_disparity_grows_down_the_road_to_most_of_its_range_and_the_sky_is_far():
    pair = render_pair("driving", W, H, seed=1)
    road = pair.disparity[:, 8]  # the left column: road (or kerb) below the horizon, facades above it
    full = CLASSES["driving"].disparities * W / DISPARITIES_WIDTH
    assert road[-1] > 0.7 * full and np.all(np.diff(road[-H // 4:]) > 0)  # nearer every row down
    assert np.nanmin(pair.disparity) < 0.1 and pair.left[:H // 8].max() > 200  # a bright sky at ~0 px


def test_clutter_has_depth_edges_everywhere():
    def edges(name: str) -> float:  # share of horizontal steps that jump more than 1 px at 640 wide
        d = render_pair(name, W, H, seed=1).disparity
        return float((np.abs(np.diff(d, axis=1)) > W / DISPARITIES_WIDTH).mean())
    assert edges("clutter") > 3 * edges("exposure")  # the everyday boxes, board and ball


def test_unknown_class_is_named():
    with pytest.raises(ValueError, match="known: slanted"):
        scene_class("marble")


def test_exposure_class_brightens_the_right_eye_only():
    photo = CLASSES["exposure"].photometry
    pair = render_pair("exposure", W, H)
    plain = render_primitives("plain", [CLASSES["exposure"].build(0.0)], CLASSES["exposure"].build(0.0), PLAIN,
                              ideal_geometry(W, H), seed=0)
    assert np.array_equal(pair.left, plain.left)
    expected = photo.right_gain * plain.right.mean() + 255 * photo.right_offset
    assert pair.right.mean() == pytest.approx(expected, rel=0.02)


def test_vignetting_darkens_the_corners():
    pair = render_pair("vignetting", W, H)
    plain = render_primitives("plain", [CLASSES["vignetting"].build(0.0)], CLASSES["vignetting"].build(0.0), PLAIN,
                              ideal_geometry(W, H), seed=0)
    corner = (slice(0, 12), slice(0, 16))
    centre = (slice(H // 2 - 6, H // 2 + 6), slice(W // 2 - 8, W // 2 + 8))
    assert pair.left[corner].mean() / plain.left[corner].mean() < 0.6
    assert pair.left[centre].mean() / plain.left[centre].mean() > 0.97


def test_noise_class_is_noisier_and_motion_blur_smears_the_moving_panel():
    def residual(img: np.ndarray, where: np.ndarray | None = None) -> float:  # high-pass energy
        step = img[:, 1:].astype(float) - img[:, :-1]
        return float(np.std(step if where is None else step[where[:, 1:] & where[:, :-1]]))
    noisy = render_pair("noise", W, H)
    dim = Photometry(light=CLASSES["noise"].photometry.light)
    quiet = render_primitives("dim", [CLASSES["noise"].build(0.0)], CLASSES["noise"].build(0.0), dim,
                              ideal_geometry(W, H), seed=0)
    assert residual(noisy.left) > 1.5 * residual(quiet.left)

    blur = CLASSES["motion-blur"]
    blurred = render_pair("motion-blur", W, H)
    sharp = render_primitives("sharp", [blur.build(0.0)], blur.build(0.0), PLAIN, ideal_geometry(W, H), seed=0)
    panel = np.abs(blurred.disparity - ideal_geometry(W, H).focal_px * 0.08 / 1.3) < 1e-3  # the panel at 1.3 m
    assert panel.sum() > 100
    assert residual(blurred.left, panel) < 0.8 * residual(sharp.left, panel)


def test_misaligned_class_turns_the_right_rows_and_keeps_the_horizontal_truth():
    """The right image's rows land 0.2-1.0 px below the rectified pose's (more on the left than on
    the right: pitch plus roll), the left image is the rectified rig's, and the truth is where each
    left pixel's point lands in the turned right image, column for column."""
    import cv2

    cls = CLASSES["misaligned"]
    w, h = 640, 480  # the class's offsets are given at this size
    turned = render_pair("misaligned", w, h, seed=2)
    plain = render_primitives("plain", [cls.build(0.0, 2)], cls.build(0.0, 2), PLAIN, ideal_geometry(w, h), seed=2)
    assert np.array_equal(turned.left, plain.left)
    shifts = [cv2.phaseCorrelate(plain.right[100:380, x:x + 160].astype(np.float64),
                                 turned.right[100:380, x:x + 160].astype(np.float64))[0] for x in (0, 240, 480)]
    dys = [dy for _, dy in shifts]
    assert 0.75 < dys[0] < 1.1 and 0.45 < dys[1] < 0.75 and 0.1 < dys[2] < 0.45, dys
    assert all(abs(dx) < 0.1 for dx, _ in shifts), shifts
    g = ideal_geometry(w, h)
    seen = np.isfinite(plain.disparity)
    assert np.array_equal(seen, np.isfinite(turned.disparity))
    # OpenCV's projection of each seen point into the turned right camera gives the same columns
    z = g.focal_px * g.baseline_m / plain.disparity[seen]
    points = (g.rays().astype(np.float64)[seen] * z[:, None]).reshape(-1, 1, 3)
    rot_w2c = cls.right_turn().T  # world -> the right camera
    tvec = -rot_w2c @ np.array([g.baseline_m, 0.0, 0.0])
    k = np.array([[g.focal_px, 0, g.cx], [0, g.focal_px, g.cy], [0, 0, 1]])
    proj, _ = cv2.projectPoints(points, cv2.Rodrigues(rot_w2c)[0], tvec, k, None)
    columns = np.nonzero(seen)[1]
    assert np.max(np.abs(turned.disparity[seen] - (columns - proj[:, 0, 0]))) < 2e-3
    assert 0.3 < np.nanmax(np.abs(turned.disparity - plain.disparity)) < 0.6  # the drift moves columns too


def test_the_live_rig_turns_the_right_eye_in_the_misaligned_scene(monkeypatch: pytest.MonkeyPatch):
    """The simulated unit looking at the misaligned class: its left image is the one it sees with the
    right eye where its calibration says; its right image's rows 0.4-0.8 px lower in the middle."""
    import cv2

    from stereocam.device_sim.rig import scene

    def capture() -> tuple[np.ndarray, np.ndarray]:
        rig = SensorRig(5, true_calibration(5))
        rig.set_format(640, 480)
        return rig.capture(0.0, Scene.MISALIGNED, 4000, 0, 7)

    left, right = capture()
    monkeypatch.setattr(scene, "right_turn", lambda view: np.eye(3))
    left0, right0 = capture()
    assert np.array_equal(left, left0)
    middle = (slice(120, 360), slice(240, 400))
    (dx, dy), _ = cv2.phaseCorrelate(right0[middle].astype(np.float64), right[middle].astype(np.float64))
    assert 0.4 < dy < 0.8 and abs(dx) < 0.2, (dx, dy)


def test_the_simulator_serves_a_class_by_name_with_its_truth():
    import stereocam
    from stereocam.device_sim import SimulatedCamera
    from stereocam.protocol.params import Output

    sim = SimulatedCamera(seed=4, serial="SCENES-1", scene="motion-blur")
    try:
        assert sim.scene is Scene.MOTION_BLUR
        with stereocam.open("sim://?serial=SCENES-1", timeout=3.0) as cam:
            cam.configure(width=W, height=H, outputs=int(Output.LEFT | Output.RIGHT))
            cam.start()
            frame = cam.get_frame(timeout=60.0)
            cam.stop()
        truth = sim.ground_truth(frame.sequence)
    finally:
        sim.close()
    assert truth is not None and frame.left is not None
    assert (truth.disparity_px > 0).mean() > 0.95  # the class fills the view
    assert truth.occluded is not None and 0 < truth.occluded.mean() < 0.3
    assert explained_occlusions(truth.disparity_px, truth.occluded) > 0.99


def explained_occlusions(disparity: np.ndarray, occluded: np.ndarray) -> float:
    """Fraction of the occluded pixels with a cause in the truth itself: left of the right image
    (x < d), or a nearer surface to their right that covers them in the right view (at x' > x
    with d' - (x' - x) >= d: it lands at or left of the point's own right-image column)."""
    ys, xs = np.nonzero(occluded)
    w = disparity.shape[1]
    explained = 0
    for y, x in zip(ys, xs):
        d = disparity[y, x]
        right = np.arange(x + 1, min(w, x + 1 + int(np.ceil(disparity.max()))))
        rows = disparity[max(0, y - 1):y + 2, right]  # the rectified rows match to within a pixel
        covered = right.size and (rows - (right - x)[None, :] >= d - 1.0).any()
        explained += bool(x < d + 1.0 or covered)
    return explained / max(1, len(ys))


def test_a_sim_url_names_the_class_and_an_unknown_one_is_refused():
    import stereocam
    from stereocam.protocol.errors import ConfigError

    with stereocam.open("sim://?seed=4&scene=low-texture", timeout=3.0) as cam:
        assert cam.info() is not None
    with pytest.raises(ConfigError, match="known: lab"):
        stereocam.open("sim://?seed=4&scene=marble", timeout=3.0)
