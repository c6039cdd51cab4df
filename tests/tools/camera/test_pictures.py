"""The disparity picture carries a colour bar whose ticks read depth in metres; the demo says when it fell short."""
from __future__ import annotations

from types import SimpleNamespace

import cv2
import pytest

import stereocam
from stereocam.tools.demo.cli import keep_up_note
from stereocam.tools.camera.pictures import depth_ticks, disparity_range, save_disparity_png
from tests.support.device import SMALL


@pytest.fixture(scope="module")
def frame():
    with stereocam.open("sim://?seed=4", timeout=2.0) as cam:
        cam.configure(**SMALL)
        cam.start()
        return cam.get_frame(timeout=60)


def test_depth_ticks_are_metres_inside_the_searched_range(frame):
    ticks = depth_ticks(frame)
    lo, hi = disparity_range(frame)
    g = frame.geometry
    assert len(ticks) >= 3
    for d, z in ticks:
        assert lo < d <= hi and z == pytest.approx(g.focal_px * g.baseline_m / d, rel=1e-3)
    assert [z for _, z in ticks] == sorted(z for _, z in ticks)  # near to far
    gaps = [a[0] - b[0] for a, b in zip(ticks, ticks[1:])]
    assert min(gaps) >= (hi - lo) / 7 - 1e-9  # readable, not piled up at the far end


def test_disparity_png_has_a_colour_bar(frame, tmp_path):
    path = save_disparity_png(frame, tmp_path / "d.png")
    img = cv2.imread(str(path))
    assert img.shape[1] > frame.width + 40  # the image plus a labelled bar beside it
    strip = img[img.shape[0] // 4: 3 * img.shape[0] // 4, frame.width + 5:]
    assert strip.std() > 20  # the bar and its labels are there, not a blank margin


def test_demo_says_plainly_when_the_machine_fell_short():
    assert "could not keep up" in keep_up_note(6.3, 15, 36) and "6.3 of the 15 fps" in keep_up_note(6.3, 15, 36)
    assert keep_up_note(14.9, 15, 0).startswith("kept up")


def test_calibration_report_names_views_by_file_and_calls_out_the_worst():
    from stereocam.tools.calibration.report import short_label, worst_views
    from stereocam.tools.calibration.solve import ViewRecord

    views = [ViewRecord(i, f"/data/left_{i:02d}.jpg|/data/right_{i:02d}.jpg", "used", rms_left=0.1 + i / 100,
                        rms_right=0.1) for i in range(6)]
    views[2].rms_right = 0.7  # the outlier a reader must find by name
    views.append(ViewRecord(6, "left_06.jpg|right_06.jpg", "dropped", reason="epipolar 2.0 px > 1.0 px"))
    worst = worst_views(SimpleNamespace(views=views), 2)  # what worst_views reads of a CalibrationResult
    assert [(short_label(v), name, round(px, 2)) for v, name, px in worst] == [
        ("left_02.jpg", "right reprojection", 0.7), ("left_05.jpg", "left reprojection", 0.15)]
