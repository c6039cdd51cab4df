"""Calibration stored on the simulated unit: its flash, its true calibration, power loss, reboots.

What any device shows through the protocol (read-back, restore, refusals) is in
test_calibration_on_device.py, which runs against every transport and ``--device``."""
from __future__ import annotations

import dataclasses
import zlib

import numpy as np
import pytest

import stereocam
from stereocam.device_sim import SimulatedCamera
from stereocam.camera import Camera
from stereocam.device_sim.links.inprocess import InProcessTransport
from stereocam.protocol import messages as m
from stereocam.protocol.calibration import CalibrationFormatError
from stereocam.protocol.errors import ErrorCode

from tests.support.faults import FaultyTransport, PacketFilter

pytestmark = pytest.mark.sim_only("reads the simulator's flash and true calibration")

SMALL = dict(width=320, height=240, num_disparities=32, block_size=11)


def shifted(calib, dfx: float = 3.0):
    """A plausible different calibration: focal lengths moved by ``dfx`` px."""
    K = calib.K_left.copy()
    K[0, 0] += dfx
    return dataclasses.replace(calib, K_left=K)


def one_frame(cam: Camera) -> stereocam.Frame:
    cam.set_trigger_mode("software")
    cam.start()
    cam.trigger()
    f = cam.get_frame(timeout=30)
    cam.stop()
    return f


@pytest.fixture
def unit(tmp_path):
    sim = SimulatedCamera(serial="CAL-1", seed=61, flash_path=tmp_path / "unit.flash")
    cam = Camera(InProcessTransport(sim))
    cam.configure(**SMALL)
    yield cam, sim
    cam.close()


def test_factory_calibrated_unit_reports_and_uses_its_calibration(unit):
    cam, sim = unit
    stored = cam.read_calibration()
    assert stored.source == "factory" and stored.generation == 1
    assert stored.body == sim.true_calibration().to_bytes()
    assert cam.info().calibration_id == stored.calibration_id == m.calib_id(stored.body)
    assert cam.read_calibration("user") is None
    f = one_frame(cam)
    assert f.rectified and f.geometry.calibration_id == stored.calibration_id
    assert f.disparity is not None
    assert abs(f.geometry.baseline_m - sim.true_calibration().baseline_m) < 1e-6


def test_uncalibrated_unit_streams_raw_images_without_disparity(tmp_path):
    sim = SimulatedCamera(seed=62, flash_path=tmp_path / "raw.flash", factory_calibrated=False)
    with Camera(InProcessTransport(sim)) as cam:
        cam.configure(**SMALL)
        assert cam.info().calibration_id == 0
        assert cam.read_calibration() is None
        f = one_frame(cam)
    assert not f.rectified and f.geometry.calibration_id == 0
    assert f.disparity is None and f.left.shape == (240, 320)
    with pytest.raises(ValueError, match="no disparity"):
        f.depth()


def test_raw_images_on_request(unit):
    cam, _ = unit
    cam.configure(rectify=0)
    f = one_frame(cam)
    assert not f.rectified and f.disparity is None and f.geometry.calibration_id != 0


def test_write_read_back_and_restore(unit):
    cam, sim = unit
    factory = cam.read_calibration()
    new = shifted(sim.true_calibration())
    written = cam.write_calibration(new)
    assert written.source == "user" and written.generation == 1 and written.body == new.to_bytes()
    assert cam.info().calibration_id == written.calibration_id != factory.calibration_id
    assert one_frame(cam).geometry.calibration_id == written.calibration_id
    again = cam.write_calibration(shifted(new))  # the other slot, next generation
    assert again.generation == 2
    restored = cam.restore_factory_calibration()
    assert restored.source == "factory" and restored.body == factory.body
    assert one_frame(cam).geometry.calibration_id == factory.calibration_id


def test_power_loss_at_every_flash_step_keeps_the_previous_calibration(unit):
    cam, sim = unit
    first = cam.write_calibration(shifted(sim.true_calibration(), 2.0))
    flash = sim.calibration.flash
    steps0 = flash.steps
    cam.write_calibration(shifted(sim.true_calibration(), 4.0))
    steps = flash.steps - steps0
    cam.restore_factory_calibration()
    first = cam.write_calibration(shifted(sim.true_calibration(), 2.0))
    assert steps >= 3
    candidate = shifted(sim.true_calibration(), 6.0)
    for k in range(steps):
        flash.power_loss_after(k)
        with pytest.raises(stereocam.DeviceError) as exc:
            cam.write_calibration(candidate)
        flash.power_loss_after(None)
        assert exc.value.code == ErrorCode.STORAGE, k
        now = cam.read_calibration()
        assert now.body == first.body, f"cut after step {k} lost the previous record"
        assert cam.info().calibration_id == first.calibration_id
    assert cam.write_calibration(candidate).body == candidate.to_bytes()  # power back: it works


def test_read_back_that_differs_is_a_verification_error(tmp_path):
    sim = SimulatedCamera(seed=63, flash_path=tmp_path / "v.flash")
    link = FaultyTransport(InProcessTransport(sim))
    with Camera(link) as cam:
        def corrupt_read_back(p):
            if p.msg_type == m.MsgType.CALIB_DATA and len(p.payload) > 40:
                payload = bytearray(p.payload)
                payload[-1] ^= 0xFF
                from stereocam.protocol.framing import encode_frame
                return encode_frame(p.msg_type, p.request_id, bytes(payload), p.flags)
            return None

        link.set_manipulator(read=PacketFilter(corrupt_read_back))
        with pytest.raises(stereocam.StereoCamError):  # the tool never reports success
            cam.write_calibration(shifted(sim.true_calibration()))


def test_calibration_survives_a_reboot(tmp_path):
    path = tmp_path / "persist.flash"
    sim = SimulatedCamera(serial="P1", seed=64, flash_path=path)
    with Camera(InProcessTransport(sim)) as cam:
        written = cam.write_calibration(shifted(sim.true_calibration()))
    rebooted = SimulatedCamera(serial="P1", seed=64, flash_path=path)
    with Camera(InProcessTransport(rebooted)) as cam:
        assert cam.info().calibration_id == written.calibration_id
        cam.configure(**SMALL)
        f = one_frame(cam)
        assert f.geometry.calibration_id == written.calibration_id
        assert np.isfinite(f.geometry.focal_px)


def test_restore_without_factory_record_is_refused(tmp_path):
    sim = SimulatedCamera(seed=65, flash_path=tmp_path / "n.flash", factory_calibrated=False)
    with Camera(InProcessTransport(sim)) as cam:
        written = cam.write_calibration(shifted(sim.true_calibration()))
        with pytest.raises(stereocam.DeviceError) as exc:
            cam.restore_factory_calibration()
        assert exc.value.code == ErrorCode.BAD_STATE and "factory" in str(exc.value)
        assert cam.read_calibration().body == written.body  # the user record is untouched


def test_refused_target_keeps_the_staging(unit):
    cam, sim = unit
    body = shifted(sim.true_calibration()).to_bytes()
    cam.request(m.CalibWrite(0, len(body), body))
    with pytest.raises(stereocam.DeviceError) as exc:
        cam.request(m.CalibCommit(m.CalibSource.FACTORY, len(body), zlib.crc32(body)))  # locked
    assert exc.value.code == ErrorCode.BAD_STATE
    state = cam.request(m.CalibCommit(m.CalibSource.USER, len(body), zlib.crc32(body)))
    assert state.source == m.CalibSource.USER and cam.read_calibration().body == body


def test_host_depth_uses_the_calibration_read_from_the_device(tmp_path):
    from stereocam.protocol.framing import encode_frame
    from stereocam.protocol.rectification import stereo_rectify

    sim = SimulatedCamera(seed=66, flash_path=tmp_path / "g.flash")
    link = FaultyTransport(InProcessTransport(sim))
    with Camera(link) as cam:
        cam.configure(**SMALL)
        honest = one_frame(cam)
        stored = cam.read_calibration()
        expect = stereo_rectify(stored.calibration.scaled(320, 240))
        assert honest.calibration.image_size == (320, 240)
        assert honest.geometry.focal_px == pytest.approx(expect.focal_px)
        assert honest.geometry.baseline_m == pytest.approx(expect.baseline_m)
        assert cam.geometry_mismatches == 0

        def lie_about_focal(p):  # a device whose frames disagree with its own stored calibration
            if p.msg_type == m.MsgType.FRAME_BEGIN:
                begin = m.FrameBegin.unpack(p.payload)
                forged = dataclasses.replace(begin, focal_px=begin.focal_px * 1.1)
                return encode_frame(p.msg_type, p.request_id, forged.pack(), p.flags)
            return None

        link.set_manipulator(read=PacketFilter(lie_about_focal))
        f = one_frame(cam)
    assert cam.geometry_mismatches == 1
    assert f.geometry.focal_px == pytest.approx(expect.focal_px)  # the stored calibration wins


@pytest.mark.parametrize("size", [("a", 3), None, (1, 2, 3), (1280.9, 960.2), "ab", (True, 1), (0, 960)])
def test_a_malformed_image_size_is_a_calibration_format_error_naming_it(size):
    good = SimulatedCamera(seed=66).true_calibration()
    with pytest.raises(CalibrationFormatError, match="image_size"):
        dataclasses.replace(good, image_size=size)
    assert dataclasses.replace(good, image_size=(np.int64(640), 480.0)).image_size == (640, 480)


@pytest.mark.parametrize("field, value, problem", [
    ("K_left", "garbage", "K_left"), ("image_size", (70000, 1), "image_size"), ("D_left", np.zeros(2), "D_left"),
    ("lens_model", "xx", "lens model"), ("T", np.array([np.nan, 0.0, 0.0]), "T"), ("R", np.zeros((3, 3)), "R"),
])
def test_a_calibration_changed_after_construction_is_checked_before_it_is_written(unit, field, value, problem):
    cam, sim = unit
    before = cam.read_calibration().body, cam.read_calibration("user")
    calib = shifted(sim.true_calibration())
    setattr(calib, field, value)
    with pytest.raises(CalibrationFormatError, match=problem):
        cam.write_calibration(calib)
    assert (cam.read_calibration().body, cam.read_calibration("user")) == before  # nothing was sent
