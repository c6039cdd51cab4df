"""Firmware updates through the protocol: the unit runs what it booted, refuses bad images with a
NACK naming the reason, takes one update at a time, keeps streaming during the transfer, and comes
through unplugs (USB power) at random moments of an update with a valid image every time."""
from __future__ import annotations

import dataclasses
import hashlib
import random
import threading
import time

import pytest

import stereocam
import stereocam.device_sim.usb as simusb
from stereocam import firmware_update as fw
from stereocam.device_sim import SimulatedCamera
from stereocam.device_sim.boot.factory import DEV_SIGNING_KEY
from stereocam.protocol import messages as m
from stereocam.protocol.errors import DeviceError, ErrorCode, StereoCamError
from stereocam.protocol.firmware_image import ImageFault, auto_security_counter, build_image
from stereocam.protocol.update_messages import BootMode, SlotState
from stereocam.tools.conformance.budget import time_factor
from tests.support.device import SMALL
from tests.support.firmware import OTHER_KEY, build, image

pytestmark = pytest.mark.sim_only("reboots and power-cycles the simulated unit")


@pytest.fixture
def unit():
    sim = SimulatedCamera(serial="FW-1", seed=21)
    cam = stereocam.open("sim://?serial=FW-1", timeout=2.0)
    yield sim, cam
    cam.close()
    sim.close()


def test_update_changes_what_the_unit_reports_and_does_and_a_signed_rollback_goes_back(unit):
    sim, cam = unit
    assert cam.config()["fps"] == 30 and cam.info().protocol_version == (1, 3)
    no_calib = image("1.2.0", code_size=5000, fps=12)
    result = cam.update_firmware(no_calib)
    info = cam.info()
    assert (result.version, result.slot, info.firmware_version) == ("1.2.0", "B", "1.2.0")
    assert cam.config()["fps"] == 12  # the new build's parameter defaults
    assert sim.booted.mode == BootMode.NORMAL and sim.firmware_version == "1.2.0"
    st = cam.firmware_status()
    assert [(s.slot, s.state, s.version) for s in st.slots] == [("A", SlotState.STANDBY, "1.1.0"),
                                                                 ("B", SlotState.ACTIVE, "1.2.0")]
    with pytest.raises(fw.ImageRefusedError) as refused:  # the old build again: a downgrade
        cam.update_firmware(image("1.1.0"))
    assert refused.value.fault == ImageFault.ROLLBACK
    back = cam.update_firmware(image("1.1.0", counter=auto_security_counter("1.2.0")))
    assert back.version == cam.info().firmware_version == "1.1.0" and back.slot == "A"
    assert cam.config()["fps"] == 30


def test_capabilities_follow_the_booted_build(unit):
    _, cam = unit
    assert cam.read_calibration() is not None
    b = build("1.3.0")
    lean = build_image(dataclasses.replace(b, capabilities=b.capabilities & ~m.Capability.CALIBRATION),
                       DEV_SIGNING_KEY, target="STOC-SIM")  # a build without calibration storage
    cam.update_firmware(lean)
    assert not cam.info().capabilities & m.Capability.CALIBRATION
    with pytest.raises(DeviceError) as info:
        cam.request(m.CalibRead(0, 0, 16))
    assert info.value.code == ErrorCode.UNKNOWN_TYPE


def test_recovery_is_always_there_and_takes_an_update(unit):
    sim, cam = unit
    sim.reboot(recovery=True)  # the recovery strap held at power-on
    cam.reconnect()
    info = cam.info()
    assert (info.firmware_version, info.capabilities) == ("recovery", m.Capability.FIRMWARE_UPDATE)
    with pytest.raises(DeviceError) as refused:
        cam.start()
    assert refused.value.code == ErrorCode.UNKNOWN_TYPE
    assert cam.firmware_status().running == "recovery"
    assert cam.update_firmware(image("1.2.0")).version == cam.info().firmware_version == "1.2.0"


@pytest.mark.parametrize("bad, fault", [
    (image("1.2.0", key=None), ImageFault.UNSIGNED), (image("1.2.0", code_size=900)[:-1], ImageFault.TRUNCATED),
    (image("1.2.0", key=OTHER_KEY), ImageFault.WRONG_KEY), (image("1.2.0", target="STOC-PRO"), ImageFault.WRONG_TARGET),
    (image("1.0.9"), ImageFault.ROLLBACK),
    (bytes(b ^ (i == 700) for i, b in enumerate(image("1.2.0", code_size=900))), ImageFault.TAMPERED)])
def test_bad_images_are_refused_with_a_nack_naming_the_reason(unit, bad, fault):
    sim, cam = unit
    cam.update_firmware(image("1.1.1", code_size=10))  # the counter is now 1.1.1's: 1.0.9 is a downgrade
    before = cam.firmware_status()
    state = sim.update.states.read()
    with pytest.raises(fw.ImageRefusedError) as refused:
        fw.transfer(cam.request, bad)
    assert refused.value.fault == fault and fault.name.lower() in str(refused.value)
    assert sim.update.states.read() == state  # no slot changed state
    after = cam.firmware_status()
    assert after.running == before.running == "B" and after.slots[1] == before.slots[1]
    assert after.slots[0] == before.slots[0]  # the fallback image is kept: refused before the slot was written
    sim.reboot()
    cam.reconnect()
    assert cam.info().firmware_version == "1.1.1"


def test_a_second_update_while_one_is_in_progress_is_refused(unit):
    _, cam = unit
    first, second = image("1.2.0", code_size=4000), image("1.3.0")
    cam.request(m.UpdateBegin(len(first), hashlib.sha256(first).digest()))
    cam.request(m.UpdateData(0, first[:1000]))
    with pytest.raises(fw.FirmwareUpdateError, match="BUSY.*in progress"):
        cam.update_firmware(second)
    assert cam.firmware_status().transfer == (1000, len(first))
    assert cam.update_firmware(first).resumed_from == 1000  # the same image resumes


def test_an_update_cut_after_its_reboot_is_finished_by_the_next_run(unit):
    sim, cam = unit
    new = image("1.2.0", code_size=2000)
    fw.transfer(cam.request, new)
    cam.request(m.UpdateActivate())
    fw.await_reboot(cam, 10.0)  # the host dies here: the unit runs 1.2.0 on trial, unconfirmed
    assert cam.firmware_status().mode == BootMode.TRIAL
    with pytest.raises(fw.FirmwareUpdateError, match="on trial"):
        cam.update_firmware(image("1.3.0"))
    result = cam.update_firmware(new)
    assert (result.version, result.resumed_from) == ("1.2.0", len(new)) and sim.booted.mode == BootMode.NORMAL


def test_the_running_image_keeps_streaming_during_the_transfer(unit):
    _, cam = unit
    cam.configure(**SMALL, fps=20)
    cam.start()
    cam.get_frame(timeout=30)
    frames, done = [], threading.Event()

    def collect():
        while not done.is_set():
            try:
                frames.append(cam.get_frame(timeout=1.0))
            except StereoCamError:
                pass

    t = threading.Thread(target=collect)
    t.start()
    t0 = time.monotonic()
    fw.transfer(cam.request, image("1.2.0", code_size=1 << 20))
    elapsed = time.monotonic() - t0
    done.set()
    t.join()
    assert len(frames) >= max(2, int(elapsed * 20 * 0.3 / time_factor())), (len(frames), elapsed)  # 30% of 20 fps
    assert cam.status().streaming


def test_unplug_at_random_moments_of_a_usb_update(usb_bus):
    sim = SimulatedCamera(serial="FW-USB-CUT", seed=22)
    calibration = sim.calibration.record.body
    images = [image(f"1.2.{i}", code_size=192 * 1024) for i in range(13)]  # each try a newer one
    allowed = {sim.booted.image.sha256, *(hashlib.sha256(i).digest() for i in images)}
    rng = random.Random(1313)
    handle = simusb.plug(sim)
    with stereocam.open("usb://?serial=FW-USB-CUT", timeout=1.0) as cam:
        full = cam.update_firmware(images[0]).seconds  # an uninterrupted update, to aim the cuts
    handle.unplug()
    outcomes = []
    for n in range(12):
        handle = simusb.plug(sim)
        cam = stereocam.open("usb://?serial=FW-USB-CUT", timeout=1.0)
        worker = threading.Thread(target=_try_update, args=(cam, images[n + 1], outcomes))
        worker.start()
        time.sleep(rng.uniform(0.0, 1.1 * full))
        handle.unplug()  # bus power goes with the cable
        sim.power_cut()
        worker.join(timeout=30)
        cam.close()
        sim.power_on()
        assert sim.booted.mode != BootMode.RECOVERY and sim.booted.image.sha256 in allowed, sim.booted.trace
        assert sim.calibration.record.body == calibration
        outcomes[-1] += f" -> boots {sim.firmware_version} ({sim.booted.mode.name.lower()})"
    handle = simusb.plug(sim)
    with stereocam.open("usb://?serial=FW-USB-CUT", timeout=1.0) as cam:
        # the last image again: installed, or (cut after its reboot) checked and confirmed where it runs on trial
        assert cam.update_firmware(images[-1]).version == cam.info().firmware_version == "1.2.12"
        assert cam.firmware_status().mode == BootMode.NORMAL
    handle.unplug()
    sim.close()
    print(f"\nUSB unplug at random moments of a {full:.2f} s update: " + "; ".join(outcomes))


def _try_update(cam, data: bytes, outcomes: list[str]) -> None:
    try:
        fw.update(cam, data, reboot_timeout=2.0)
        outcomes.append("update done")
    except StereoCamError as exc:
        outcomes.append(f"update cut: {type(exc).__name__}")
