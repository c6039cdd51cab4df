"""A unit whose firmware only knows calibration body version 1 refuses a version-2 body cleanly."""
from __future__ import annotations

import struct

from stereocam.camera import Camera
from stereocam.device_sim import SimulatedCamera
from stereocam.device_sim.calibration import acceptance as calib_service  # where the firmware parses a body
from stereocam.device_sim.links.inprocess import InProcessTransport
from stereocam.device_sim.rig.sensor import BOARD
from stereocam.protocol.calibration import CalibrationFormatError, StereoCalibration
from stereocam.tools.calibration.solve import SolveConfig
from stereocam.tools.calibration.device import EXIT_WRITE, calibrate_device


class _Version1Firmware(StereoCalibration):
    """The body parser of firmware built before version 2: it accepts version 1 only."""

    @classmethod
    def from_bytes(cls, data: bytes) -> StereoCalibration:
        if struct.unpack_from("<H", data)[0] != 1:
            raise CalibrationFormatError(f"unsupported calibration body version {struct.unpack_from('<H', data)[0]}")
        return StereoCalibration.from_bytes(data)


def test_old_firmware_refuses_the_new_body_and_keeps_its_calibration(tmp_path, monkeypatch) -> None:
    sim = SimulatedCamera(seed=77, flash_path=tmp_path / "old.flash", scene="board")  # factory calibrated
    with Camera(InProcessTransport(sim), timeout=2.0) as cam:
        before = cam.read_calibration()
        monkeypatch.setattr(calib_service, "StereoCalibration", _Version1Firmware)
        config = SolveConfig(max_views=12, lens_model="plumb_bob")  # the refusal, not the model race
        code, result, verdict = calibrate_device(cam, BOARD, config, tmp_path, size=(640, 480), fps=20)
        assert code == EXIT_WRITE and result is not None and result.passed
        assert "BAD_PAYLOAD" in verdict and "version 2" in verdict and f"{before.calibration_id:08x}" in verdict
        after = cam.read_calibration()
        assert after.body == before.body and cam.info().calibration_id == before.calibration_id
