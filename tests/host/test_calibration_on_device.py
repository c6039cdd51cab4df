"""The calibration a unit stores, through the protocol alone: any device, any transport.

Every test leaves the unit as it found it: the user record it had is written back, or the
factory record is restored if it had none (the ``kept`` fixture).
"""
from __future__ import annotations

import dataclasses
import zlib

import pytest

import stereocam
from stereocam.protocol import messages as m
from stereocam.protocol.errors import ErrorCode


def shifted(calib, dfx: float = 3.0):
    """A plausible different calibration: the left focal length moved by ``dfx`` px."""
    K = calib.K_left.copy()
    K[0, 0] += dfx
    return dataclasses.replace(calib, K_left=K)


@pytest.fixture
def kept(cam):
    """The camera, its active calibration, and a promise to put back what it stored."""
    if not cam.info().capabilities & m.Capability.CALIBRATION:
        pytest.skip("the device does not advertise calibration storage")
    active = cam.read_calibration()
    if active is None:
        pytest.skip("the device holds no calibration to start from")
    user = cam.read_calibration("user")
    yield cam, active
    if user is not None:
        if (cam.read_calibration("user") or user).body != user.body or cam.read_calibration().source != "user":
            cam.write_calibration(user.calibration)
    elif cam.read_calibration().source != "factory" and cam.read_calibration("factory") is not None:
        cam.restore_factory_calibration()


def test_active_is_the_user_record_if_any_else_the_factory_one(kept):
    cam, active = kept
    user, factory = cam.read_calibration("user"), cam.read_calibration("factory")
    expected = user if user is not None else factory
    assert active.body == expected.body and active.source == expected.source
    assert cam.info().calibration_id == active.calibration_id == m.calib_id(active.body)


def test_write_reads_back_byte_for_byte_and_frames_carry_the_new_id(kept):
    cam, active = kept
    written = cam.write_calibration(shifted(active.calibration))
    assert written.source == "user" and written.body == shifted(active.calibration).to_bytes()
    assert cam.read_calibration().body == written.body
    assert cam.info().calibration_id == written.calibration_id != active.calibration_id
    cam.set_trigger_mode("software")
    cam.start()
    cam.trigger()
    frame = cam.get_frame(timeout=10)
    cam.stop()
    assert frame.geometry.calibration_id == written.calibration_id


def test_restore_brings_back_the_factory_record(kept):
    cam, active = kept
    factory = cam.read_calibration("factory")
    if factory is None:
        pytest.skip("no factory record on this unit")
    cam.write_calibration(shifted(active.calibration, 5.0))
    restored = cam.restore_factory_calibration()
    assert restored.body == factory.body and restored.source == "factory"
    assert cam.read_calibration("user") is None


@pytest.mark.parametrize("tamper", [
    pytest.param(lambda body, crc: (len(body), crc ^ 1), id="crc"),
    pytest.param(lambda body, crc: (len(body) + 1, crc), id="length"),
])
def test_a_commit_whose_length_or_crc_disagree_changes_nothing(kept, tamper):
    cam, active = kept
    body = shifted(active.calibration).to_bytes()
    cam.request(m.CalibWrite(0, len(body), body))
    total, crc = tamper(body, zlib.crc32(body))
    with pytest.raises(stereocam.DeviceError) as exc:
        cam.request(m.CalibCommit(m.CalibSource.USER, total, crc))
    assert exc.value.code == ErrorCode.BAD_PAYLOAD
    assert cam.read_calibration().body == active.body


def test_an_unusable_body_and_a_gap_are_refused(kept):
    cam, active = kept
    junk = b"\x07" * 248
    cam.request(m.CalibWrite(0, len(junk), junk))
    with pytest.raises(stereocam.DeviceError) as exc:
        cam.request(m.CalibCommit(m.CalibSource.USER, len(junk), zlib.crc32(junk)))
    assert exc.value.code == ErrorCode.BAD_PAYLOAD
    cam.request(m.CalibWrite(0, 200, b"\x00" * 100))
    with pytest.raises(stereocam.DeviceError) as exc:
        cam.request(m.CalibWrite(150, 200, b"\x00" * 50))  # a hole at 100..150
    assert exc.value.code == ErrorCode.BAD_STATE
    assert cam.read_calibration().body == active.body


def test_the_write_protected_factory_record_is_refused(kept):
    cam, active = kept
    with pytest.raises(stereocam.DeviceError) as exc:
        cam.write_calibration(shifted(active.calibration), target="factory")
    assert exc.value.code == ErrorCode.BAD_STATE
    assert cam.read_calibration().body == active.body
