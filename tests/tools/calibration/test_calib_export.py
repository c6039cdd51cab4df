"""camera_info for every stream size (calibrate in device mode, calibration export), the factory
record of a device attempt, and a save failure after a successful write."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from stereocam.device_sim import SimulatedCamera
from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.rectification import stereo_rectify
from stereocam.tools.calibration import calibrate
from stereocam.tools import cli
from stereocam.tools.factory.db import FactoryDB


def _matrix(text: str, key: str) -> np.ndarray:
    m = re.search(rf"{key}:\n  rows: (\d+)\n  cols: (\d+)\n  data: \[(.*)\]", text)
    return np.array([float(v) for v in m.group(3).split(",")]).reshape(int(m.group(1)), int(m.group(2)))


def test_export_writes_camera_info_that_matches_the_unit_frames(tmp_path: Path) -> None:
    assert cli.main(["calibration", "export", "sim://?seed=5", "--size", "320x240", "--out", str(tmp_path)]) == 0
    truth = SimulatedCamera(seed=5).true_calibration()
    text = (tmp_path / "right_320x240.yaml").read_text()
    assert "image_width: 320" in text and "distortion_model: plumb_bob" in text
    expect = stereo_rectify(truth.scaled(320, 240))
    np.testing.assert_allclose(_matrix(text, "projection_matrix"), expect.P2, rtol=1e-12)
    np.testing.assert_allclose(_matrix(text, "camera_matrix"), truth.scaled(320, 240).K_right, rtol=1e-12)
    assert cli.main(["calibration", "export", "sim://?seed=5", "--out", str(tmp_path / "all")]) == 0
    names = {p.name for p in (tmp_path / "all").iterdir()}
    assert {"left_1280x960.yaml", "left_640x480.yaml", "left_320x240.yaml", "right_160x120.yaml",
            "calibration.json"} <= names


def _device(tmp_path: Path, *extra: str) -> int:
    return cli.main(["calibrate", "sim://?seed=74&scene=board", "--out", str(tmp_path / "out"), "--size", "640x480", "--max-views", "12",
                           "-q", "--db", str(tmp_path / "f.sqlite"), "--station", "st-3", *extra])


def test_device_attempt_is_recorded_with_the_blob_and_camera_info_for_each_size(tmp_path: Path) -> None:
    assert _device(tmp_path) == 0
    with FactoryDB(str(tmp_path / "f.sqlite")) as db:
        (row,) = db.attempts()
    assert row.mode == "device" and row.passed and row.written and row.verified and row.station == "st-3"
    stored = StereoCalibration.from_bytes(row.calibration)
    assert stored.image_size == (640, 480) and abs(stored.baseline_m - row.baseline_m) < 1e-12
    info = tmp_path / "out" / "camera_info"
    for w, h in ((1280, 960), (640, 480), (320, 240)):
        text = (info / f"left_{w}x{h}.yaml").read_text()
        np.testing.assert_allclose(_matrix(text, "projection_matrix"),
                                   stereo_rectify(stored.scaled(w, h)).P1, rtol=1e-12)


def test_save_failure_after_a_successful_write_says_so_and_keeps_the_record(tmp_path: Path, monkeypatch,
                                                                             capsys) -> None:
    def disk_full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(calibrate, "write_outputs", disk_full)
    assert _device(tmp_path, "--serial", "SN-9") == calibrate.EXIT_SAVE
    err = capsys.readouterr().err
    assert "written to" in err and "saving the outputs" in err and "No space left" in err
    with FactoryDB(str(tmp_path / "f.sqlite")) as db:
        (row,) = db.attempts()
    assert row.unit_serial == "SN-9" and row.written and row.calibration is not None
    assert "saving the outputs" in row.reason
