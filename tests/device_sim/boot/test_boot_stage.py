"""The boot stage and the update service on a real flash file: trial, confirm, revert, refusals,
fallback and recovery."""
from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from stereocam.device_sim.boot.update_service import UpdateRefused
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.firmware_image import auto_security_counter
from stereocam.protocol.update_messages import BootMode, SlotState
from tests.support.firmware import OTHER_KEY, Unit, image

NEW = image("1.2.0", code_size=2000)


@pytest.fixture
def unit(tmp_path: Path) -> Unit:
    u = Unit.factory(tmp_path / "unit.flash")
    u.boot()
    return u


def _install(u: Unit, data: bytes) -> None:
    u.transfer(data)
    u.service.activate()


def test_trial_then_confirm_keeps_the_new_image(unit: Unit) -> None:
    _install(unit, NEW)
    assert unit.service.slot_info(1).state == SlotState.PENDING
    b = unit.boot()
    assert (b.slot, b.mode, b.image.build.version) == (1, BootMode.TRIAL, "1.2.0")
    assert unit.service.slot_info(1).state == SlotState.TRIAL
    unit.service.confirm()
    assert unit.states.read().counter == auto_security_counter("1.2.0")
    for _ in range(2):
        b = unit.boot()
        assert (b.slot, b.mode) == (1, BootMode.NORMAL)
    assert [unit.service.slot_info(i).state for i in (0, 1)] == [SlotState.STANDBY, SlotState.ACTIVE]


def test_an_unconfirmed_trial_reverts_at_the_next_boot(unit: Unit) -> None:
    _install(unit, NEW)
    assert unit.boot().mode == BootMode.TRIAL
    b = unit.boot()
    assert (b.slot, b.mode, b.image.build.version) == (0, BootMode.NORMAL, "1.1.0")
    assert "not confirmed" in b.trace[0]
    assert unit.service.slot_info(1).state == SlotState.STANDBY


def test_a_pending_image_that_fails_verification_never_runs(unit: Unit) -> None:
    _install(unit, NEW)
    addr = unit.layout.slot_addr(1) + 201
    assert unit.flash.read(addr, 1) != b"\x00"
    unit.flash.program(addr, b"\x00")  # bit rot in the pending image
    b = unit.boot()
    assert (b.slot, b.mode) == (0, BootMode.NORMAL) and "dropped" in b.trace[0]


def test_a_broken_active_image_falls_back_then_recovery(unit: Unit) -> None:
    _install(unit, NEW)
    unit.boot()
    unit.service.confirm()
    unit.flash.erase_sector(unit.layout.slot_addr(1))  # the active image is lost
    b = unit.boot()
    assert b.slot is None and b.mode == BootMode.RECOVERY  # slot A's 1.1.0 is below the counter
    assert unit.boot(recovery=True).mode == BootMode.RECOVERY
    _install(unit, image("1.3.0", code_size=100))  # recovery takes an update
    assert unit.boot().image.build.version == "1.3.0"


@pytest.mark.parametrize("bad, fault", [
    (image("1.2.0", key=None), "unsigned"), (NEW[:-10], "truncated"), (image("1.2.0", key=OTHER_KEY), "wrong_key"),
    (image("1.2.0", target="STOC-PRO"), "wrong_target"), (image("1.0.0"), "rollback")])
def test_header_faults_are_refused_before_the_flash_changes(unit: Unit, bad: bytes, fault: str) -> None:
    _install(unit, image("1.1.5", code_size=10))
    unit.boot()
    unit.service.confirm()  # now the counter is 1.1.5's and slot A holds the previous image
    before = unit.path.read_bytes()
    with pytest.raises(UpdateRefused) as info:
        unit.transfer(bad)
    assert info.value.code == ErrorCode.IMAGE_REJECTED and str(info.value).startswith(fault)
    assert unit.path.read_bytes() == before
    assert unit.service.session is None


def test_a_tampered_payload_is_refused_at_verify_and_the_boot_state_is_untouched(unit: Unit) -> None:
    bad = bytearray(NEW)
    bad[500] ^= 0x40
    state = unit.states.read()
    with pytest.raises(UpdateRefused, match="^tampered"):
        unit.transfer(bytes(bad))
    assert unit.states.read() == state and unit.service.slot_info(1).state == SlotState.EMPTY  # never written
    with pytest.raises(UpdateRefused, match="no update in progress"):
        unit.service.activate()
    assert unit.boot().slot == 0


def test_one_transfer_at_a_time_and_resume(unit: Unit) -> None:
    digest = hashlib.sha256(NEW).digest()
    s = unit.service.begin(len(NEW), digest, False)
    unit.service.data(0, NEW[:1000])
    other = image("1.3.0")
    with pytest.raises(UpdateRefused) as info:
        unit.service.begin(len(other), hashlib.sha256(other).digest(), False)
    assert info.value.code == ErrorCode.BUSY
    assert unit.service.begin(len(NEW), digest, False) is s and s.total_received == 1000  # resume
    with pytest.raises(UpdateRefused, match="continue there"):
        unit.service.data(0, NEW[:1000])
    assert unit.service.begin(len(other), hashlib.sha256(other).digest(), True).total_received == 0


def test_a_fresh_unit_refuses_an_image_older_than_the_one_it_runs(tmp_path: Path) -> None:
    """Issue 22.2: fresh from the factory (1.1.0 confirmed), the floor is already 1.1.0's counter, so a
    vendor-signed 0.9.0 is refused before a byte of the other slot changes."""
    u = Unit.factory(tmp_path / "fresh.flash")
    b = u.boot()
    assert (b.slot, b.mode, b.image.build.version) == (0, BootMode.NORMAL, "1.1.0")
    assert u.states.read().counter == auto_security_counter("1.1.0") == b.image.security_counter
    with pytest.raises(UpdateRefused, match="rollback"):
        u.transfer(image("0.9.0"))
    assert u.service.slot_info(1).state == SlotState.EMPTY


def test_a_genuine_header_over_garbage_leaves_the_fallback_image_in_place(unit: Unit) -> None:
    """Issue 22.11: after a confirmed update slot A holds the previous image (the fallback); a genuine
    header followed by garbage is refused at verify and slot A still holds, and boots, that image."""
    _install(unit, NEW)
    unit.boot()
    unit.service.confirm()
    fallback = unit.slots.image_bytes(0)
    newer = image("1.3.0", code_size=5000)
    garbage = newer[:200] + bytes(len(newer) - 200)
    with pytest.raises(UpdateRefused, match="^tampered"):
        unit.transfer(garbage)
    assert unit.slots.image_bytes(0) == fallback and unit.service.slot_info(0).state == SlotState.STANDBY
