"""The device refuses, with a NACK naming the problem, every calibration it could not use
(issue 9 item 6): nothing implausible is stored, the calibration in force stays, captures go on."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from stereocam.camera import Camera
from stereocam.device_sim import SimulatedCamera
from stereocam.device_sim.links.inprocess import InProcessTransport
from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.errors import DeviceError, ErrorCode
from stereocam.protocol.rectification import rodrigues

SMALL = dict(width=320, height=240, num_disparities=32, block_size=11)
SEED = 64


def with_k(calib: StereoCalibration, side: str = "left", **entries: float) -> StereoCalibration:
    K = getattr(calib, f"K_{side}").copy()
    where = {"fx": (0, 0), "fy": (1, 1), "cx": (0, 2), "cy": (1, 2)}
    for name, value in entries.items():
        K[where[name]] = value
    return dataclasses.replace(calib, **{f"K_{side}": K})


def with_t(calib: StereoCalibration, T) -> StereoCalibration:
    return dataclasses.replace(calib, T=np.asarray(T, float))


def with_d(calib: StereoCalibration, i: int, value: float) -> StereoCalibration:
    D = calib.D_right.copy()
    D[i] = value
    return dataclasses.replace(calib, D_right=D)


IMPLAUSIBLE = {  # name -> (make from the true calibration, what the NACK must mention)
    "T=0": (lambda c: with_t(c, [0.0, 0.0, 0.0]), "baseline"),
    "T=1e300": (lambda c: with_t(c, [-1e300, 0.0, 0.0]), "baseline"),
    "fx=1e300": (lambda c: with_k(c, fx=1e300), "fx"),
    "fx tiny": (lambda c: with_k(c, fx=1.0), "fx"),
    "fy/fx=3": (lambda c: with_k(c, "right", fy=3 * c.K_right[0, 0]), "fy"),
    "cx outside": (lambda c: with_k(c, cx=-400.0), "cx"),
    "cy outside": (lambda c: with_k(c, "right", cy=5000.0), "cy"),
    "rotation 90 deg": (lambda c: dataclasses.replace(c, R=rodrigues(np.array([0.0, np.pi / 2, 0.0])) @ c.R),
                        "rotation"),
    "k1=1e6": (lambda c: with_d(c, 0, 1e6), "distortion"),
    "vertical rig": (lambda c: with_t(c, [0.0, -0.1, 0.0]), "rectif"),
    "folding lens": (lambda c: with_d(c, 0, -8.0), "folds"),
    "folding corners": (lambda c: with_d(c, 0, -1.0), "folds"),
    "wrong aspect": (lambda c: dataclasses.replace(c.scaled(1280, 720), image_size=(1280, 720)), "image_size"),
}
PLAUSIBLE = {  # real cameras the limits must keep accepting
    "fy/fx=0.85": lambda c: with_k(c, fy=0.85 * c.K_left[0, 0]),
    "fy/fx=1.2": lambda c: with_k(c, fy=1.2 * c.K_left[0, 0]),
    "wide angle": lambda c: dataclasses.replace(with_k(with_k(c, fx=576.0, fy=576.0), "right", fx=576.0, fy=576.0),
                                                D_left=np.array([-0.25, 0.07, 0.0, 0.0, -0.008]),
                                                D_right=np.array([-0.25, 0.07, 0.0, 0.0, -0.008])),
    "half resolution": lambda c: c.scaled(640, 480),
    "30 cm baseline": lambda c: with_t(c, [-0.3, 0.0, 0.0]),
}


@pytest.fixture(scope="module")
def unit(tmp_path_factory):
    sim = SimulatedCamera(seed=SEED, flash_path=tmp_path_factory.mktemp("flash") / "u.flash")
    with Camera(InProcessTransport(sim), timeout=5.0) as cam:
        cam.configure(**SMALL)
        yield cam, sim


def one_frame(cam: Camera):
    cam.set_trigger_mode("software")
    cam.start()
    try:
        cam.trigger()
        return cam.get_frame(timeout=30)
    finally:
        cam.stop()


@pytest.mark.parametrize("case", sorted(IMPLAUSIBLE))
def test_implausible_calibration_is_refused_and_nothing_changes(unit, case) -> None:
    cam, sim = unit
    make, mentions = IMPLAUSIBLE[case]
    before = cam.read_calibration()
    with pytest.raises(DeviceError) as err:
        cam.write_calibration(make(sim.true_calibration()))
    assert err.value.code == ErrorCode.BAD_PAYLOAD
    assert mentions in err.value.device_message, err.value.device_message
    after = cam.read_calibration()
    assert after.calibration_id == before.calibration_id and after.generation == before.generation
    f = one_frame(cam)
    assert f.rectified and f.disparity is not None


@pytest.mark.parametrize("case", sorted(PLAUSIBLE))
def test_real_camera_calibrations_are_accepted(unit, case) -> None:
    cam, sim = unit
    stored = cam.write_calibration(PLAUSIBLE[case](sim.true_calibration()))
    assert cam.read_calibration().calibration_id == stored.calibration_id
    f = one_frame(cam)
    assert f.rectified and f.geometry.calibration_id == stored.calibration_id and f.disparity is not None
    cam.restore_factory_calibration()
