"""NOR flash model and the power-loss-safe calibration record store (real files in tmp_path)."""
from __future__ import annotations

from pathlib import Path

import pytest

from stereocam.device_sim.calibration.flash import (
    FlashAddressError, FlashProgramError, FlashProtectedError, NorFlash, PowerLossError,
)
from stereocam.protocol.calibration import StereoCalibration
from stereocam.device_sim.calibration.store import CalibrationStore, FactoryLockedError, StoreError
from stereocam.device_sim.calibration.truth import true_calibration

SMALL = true_calibration(1).to_bytes()          # 248 bytes: the record spans 2 pages
BIG = bytes(range(256)) * 5 + b"tail"           # 1284 bytes: 6 pages


def body(tag: int, size: int = len(SMALL)) -> bytes:
    return bytes([tag]) * size


@pytest.fixture
def path(tmp_path: Path) -> Path:
    return tmp_path / "flash.bin"


def reopen(path: Path) -> CalibrationStore:
    """A fresh store on the same file, as after a reboot."""
    return CalibrationStore(NorFlash(path))


# -- flash -------------------------------------------------------------------------------------
def test_flash_starts_erased_and_persists(path: Path) -> None:
    f = NorFlash(path, size=16384)
    assert path.stat().st_size == 16384 and f.read(100, 4) == b"\xff" * 4
    f.program(100, b"\x12\x34")
    assert NorFlash(path, size=16384).read(100, 2) == b"\x12\x34"
    with pytest.raises(FlashAddressError, match="expected 65536"):
        NorFlash(path)


def test_program_only_clears_bits(path: Path) -> None:
    f = NorFlash(path)
    f.program(0, b"\xf0")
    f.program(0, b"\x30")                       # 1->0 only: fine
    assert f.read(0, 1) == b"\x30"
    with pytest.raises(FlashProgramError, match="0->1"):
        f.program(0, b"\x31")
    assert f.read(0, 1) == b"\x30"
    f.erase_sector(0)
    assert f.read(0, 4096) == b"\xff" * 4096


def test_program_is_page_sized_and_aligned(path: Path) -> None:
    f = NorFlash(path)
    with pytest.raises(FlashAddressError, match="page boundary"):
        f.program(250, b"\x00" * 10)
    with pytest.raises(FlashAddressError, match="sector-aligned"):
        f.erase_sector(100)
    with pytest.raises(FlashAddressError, match="outside"):
        f.program(65536, b"\x00")
    f.program_range(250, b"\x00" * 300)
    assert f.steps == 3 and f.read(249, 302) == b"\xff" + b"\x00" * 300 + b"\xff"


def test_protection_is_persistent(path: Path) -> None:
    f = NorFlash(path)
    f.set_protection(8192)
    g = NorFlash(path)
    assert g.protected_below == 8192
    with pytest.raises(FlashProtectedError):
        g.erase_sector(4096)
    with pytest.raises(FlashProtectedError):
        g.program(0, b"\x00")
    g.program(8192, b"\x00")


@pytest.mark.parametrize("tear", [False, True])
def test_power_loss_leaves_file_at_cut(path: Path, tear: bool) -> None:
    f = NorFlash(path)
    f.power_loss_after(1, tear=tear)
    f.program(0, b"\x00" * 8)
    with pytest.raises(PowerLossError):
        f.program(8, b"\x00" * 8)
    expected = b"\x00" * 8 + (b"\x00" * 4 if tear else b"\xff" * 4) + b"\xff" * 4
    assert path.read_bytes()[:16] == expected
    with pytest.raises(PowerLossError):
        f.erase_sector(0)
    assert path.read_bytes()[:8] == (b"\xff" * 8 if tear else b"\x00" * 8)


# -- store -------------------------------------------------------------------------------------
def test_read_order_user_then_factory_then_none(path: Path) -> None:
    s = CalibrationStore(NorFlash(path))
    assert s.read() is None
    s.write_factory(SMALL)
    assert s.read().region == "factory"
    assert StereoCalibration.from_bytes(s.read().body).to_bytes() == SMALL
    s.write_user(body(1))
    s.write_user(BIG)
    rec = reopen(path).read()
    assert (rec.region, rec.generation, rec.body) == ("user", 2, BIG)
    s.restore_factory()
    assert reopen(path).read().body == SMALL
    assert s.write_user(body(3)).generation == 3  # never repeats after a restore (SPEC §12.1)
    assert reopen(path).write_user(body(4)).generation == 4
    s.restore_factory()
    s.restore_factory()  # nothing left to invalidate: the tombstones still number the next record
    assert reopen(path).write_user(body(5)).generation == 5


def test_restore_without_factory_record_is_refused(path: Path) -> None:
    s = CalibrationStore(NorFlash(path))
    s.write_user(body(1))
    with pytest.raises(StoreError, match="no valid factory record"):
        s.restore_factory()
    assert reopen(path).read().body == body(1)


def test_factory_lock(path: Path) -> None:
    s = CalibrationStore(NorFlash(path))
    s.write_factory(SMALL)
    s.lock_factory()
    assert reopen(path).factory_locked
    with pytest.raises(FactoryLockedError):
        reopen(path).write_factory(body(9))
    s.flash.set_protection(0)
    assert not s.factory_locked
    assert s.write_factory(body(9)).generation == 2


def test_body_size_limits(path: Path) -> None:
    s = CalibrationStore(NorFlash(path))
    with pytest.raises(StoreError, match="1..4076"):
        s.write_user(b"")
    with pytest.raises(StoreError, match="1..4076"):
        s.write_user(b"x" * 4077)
    assert s.write_user(b"x" * 4076).body == b"x" * 4076


def _prepared(path: Path, n_user: int) -> tuple[CalibrationStore, bytes]:
    """Locked factory record plus n_user user records; returns the store and the expected body."""
    s = CalibrationStore(NorFlash(path))
    s.write_factory(SMALL)
    s.lock_factory()
    expected = SMALL
    for i in range(n_user):
        expected = body(10 + i, 600 if i % 2 else 300)
        s.write_user(expected)
    return s, expected


def _steps(path: Path, n_user: int, op) -> int:
    s, _ = _prepared(path, n_user)
    before = s.flash.steps
    op(s)
    steps = s.flash.steps - before
    path.unlink()
    path.with_name(path.name + ".sr").unlink()
    return steps


@pytest.mark.parametrize("tear", [False, True])
@pytest.mark.parametrize("n_user", [0, 1, 2, 3])
@pytest.mark.parametrize("new", [SMALL, BIG], ids=["small", "big"])
def test_write_user_cut_at_every_step(path: Path, tear: bool, n_user: int, new: bytes) -> None:
    total = _steps(path, n_user, lambda s: s.write_user(new))
    assert total == 1 + -(-(20 + len(new)) // 256)     # erase + one program per page
    for n in range(total):
        s, expected = _prepared(path, n_user)
        s.flash.power_loss_after(n, tear=tear)
        with pytest.raises(PowerLossError):
            s.write_user(new)
        after = reopen(path)
        assert after.read().body == expected, f"cut after {n} steps"
        after.write_user(new)                          # the store is usable after the cut
        assert reopen(path).read().body == new
        path.unlink()
        path.with_name(path.name + ".sr").unlink()


@pytest.mark.parametrize("tear", [False, True])
def test_write_factory_cut_at_every_step(path: Path, tear: bool) -> None:
    total = 3
    for n in range(total):
        s = CalibrationStore(NorFlash(path))
        s.write_factory(SMALL)
        s.flash.power_loss_after(n, tear=tear)
        with pytest.raises(PowerLossError):
            s.write_factory(body(7))
        assert reopen(path).read().body == SMALL
        path.unlink()


@pytest.mark.parametrize("n_user", [1, 2, 3])
def test_restore_factory_cut_at_every_step(path: Path, n_user: int) -> None:
    total = _steps(path, n_user, lambda s: s.restore_factory())
    assert total == min(n_user, 2)
    for n in range(total):
        s, expected = _prepared(path, n_user)
        s.flash.power_loss_after(n)
        with pytest.raises(PowerLossError):
            s.restore_factory()
        assert reopen(path).read().body == expected      # cut: the old user record stays
        reopen(path).restore_factory()
        assert reopen(path).read().region == "factory"
        path.unlink()
        path.with_name(path.name + ".sr").unlink()


def test_corruption_anywhere_is_rejected_by_crc(path: Path) -> None:
    s, _ = _prepared(path, 0)
    s.write_user(body(1))
    newest = s.write_user(body(2))
    addr = newest.slot * 4096 + 2 * 4096
    record_len = 16 + len(SMALL) + 4
    pristine = path.read_bytes()
    for offset in range(record_len):
        data = bytearray(pristine)
        data[addr + offset] ^= 0x10
        path.write_bytes(bytes(data))
        rec = reopen(path).read()
        assert (rec.body, rec.generation) == (body(1), 1), f"flip at record byte {offset}"
    data = bytearray(pristine)
    data[addr + 100] ^= 1
    data[(1 - newest.slot) * 4096 + 2 * 4096 + 20] ^= 1  # both user records broken -> factory
    path.write_bytes(bytes(data))
    assert reopen(path).read().region == "factory"
