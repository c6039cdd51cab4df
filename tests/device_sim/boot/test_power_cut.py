"""Power cut at EVERY flash program and erase step of an update — transfer, activate, first boot,
confirm, and revert — with whole and torn steps: after each cut the unit boots a valid signed
image (the old or the new one, never neither, never recovery) and its calibration is intact.

A cut unit is powered on again (a fresh NorFlash on the same file, a fresh boot stage), booted,
and booted once more (a boot that is itself interrupted only repeats its decision).
"""
from __future__ import annotations

import collections
from pathlib import Path
from typing import Callable

import pytest

from stereocam.device_sim.calibration.flash import PowerLossError
from stereocam.protocol.firmware_image import verify_image
from stereocam.device_sim.boot.factory import DEV_SIGNING_KEY
from stereocam.protocol.update_messages import BootMode
from tests.support.firmware import Unit, copy_flash, image

NEW = image("1.2.0", code_size=3000)  # 12 pages of payload: a few KiB keeps the exhaustive run fast
NEWER = image("1.3.0", code_size=3000)  # the second update: into slot A, over the previous image

Phase = tuple[str, Callable[[Unit], None]]


def _first_boot(u: Unit) -> None:
    assert u.boot().mode == BootMode.TRIAL


def _confirm(u: Unit) -> None:
    u.service.confirm()


def _revert(u: Unit) -> None:
    assert u.boot().mode == BootMode.NORMAL  # the trial was not confirmed


UPDATE: list[Phase] = [("transfer", lambda u: u.transfer(NEW)), ("activate", lambda u: u.service.activate()),
                       ("first boot", _first_boot), ("confirm", _confirm)]
REVERT: list[Phase] = UPDATE[:3] + [("revert", _revert)]
SECOND: list[Phase] = [("transfer", lambda u: u.transfer(NEWER))] + UPDATE[1:]


@pytest.fixture(scope="module")
def templates(tmp_path_factory) -> dict[str, tuple[Path, bytes, bytes]]:
    """Flash files to start from: (path, sha256 of the image running, of the image the scenario installs).
    "factory": as shipped (slot A); "updated": after one confirmed update (B runs, A holds the old image)."""
    path = tmp_path_factory.mktemp("fw") / "factory.flash"
    unit = Unit.factory(path)
    factory_sha = unit.boot().image.sha256
    updated = path.with_name("updated.flash")
    copy_flash(path, updated)
    u = Unit(updated)
    u.boot()
    for _, run in UPDATE:
        run(u)
    new_sha = verify_image(NEW, DEV_SIGNING_KEY.public_key(), "STOC-SIM").sha256
    newer_sha = verify_image(NEWER, DEV_SIGNING_KEY.public_key(), "STOC-SIM").sha256
    return {"update": (path, factory_sha, new_sha), "revert": (path, factory_sha, new_sha),
            "second update": (updated, new_sha, newer_sha)}


def _steps_per_phase(path: Path, phases: list[Phase]) -> list[tuple[str, int]]:
    u = Unit(path)
    u.boot()
    out = []
    for name, run in phases:
        before = u.flash.steps
        run(u)
        out.append((name, u.flash.steps - before))
    return out


def _cut_and_check(path: Path, phases: list[Phase], cut: int, tear: bool, allowed: set[bytes]) -> str:
    """Run ``phases`` with power lost at step ``cut``; power on, boot twice; the phase cut."""
    u = Unit(path)
    u.boot()
    u.flash.power_loss_after(cut, tear=tear)
    for name, run in phases:  # noqa: B007 - the phase the cut hit, named below
        try:
            run(u)
        except PowerLossError:
            break
    else:
        pytest.fail(f"no flash step {cut} in the scenario")
    for _ in range(2):  # power returns; then a second power cycle
        booted = Unit(path).boot()
        assert booted.mode != BootMode.RECOVERY, f"cut at step {cut} ({name}, tear={tear}): {booted.trace}"
        data = Unit(path).slots.image_bytes(booted.slot)
        assert verify_image(data, DEV_SIGNING_KEY.public_key(), "STOC-SIM").sha256 in allowed
        assert booted.image.sha256 in allowed
    assert Unit(path).calibration_intact(), f"calibration damaged by a cut at step {cut} ({name})"
    return name


@pytest.mark.parametrize("scenario", ["update", "revert", "second update"])
def test_power_cut_at_every_flash_step(templates, tmp_path: Path, scenario: str) -> None:
    src, old_sha, new_sha = templates[scenario]
    phases = {"update": UPDATE, "revert": REVERT, "second update": SECOND}[scenario]
    copy_flash(src, tmp_path / "probe.flash")
    per_phase = _steps_per_phase(tmp_path / "probe.flash", phases)
    total = sum(n for _, n in per_phase)
    tried: collections.Counter[str] = collections.Counter()
    for tear in (False, True):
        for cut in range(total):
            path = tmp_path / f"cut{cut}-{tear}.flash"
            copy_flash(src, path)
            tried[_cut_and_check(path, phases, cut, tear, {old_sha, new_sha})] += 1
            for suffix in ("", ".sr", ".otp"):
                Path(f"{path}{suffix}").unlink(missing_ok=True)
    expected = {name: 2 * n for name, n in per_phase}
    assert dict(tried) == {k: v for k, v in expected.items() if v}
    assert all(n > 0 for _, n in per_phase)  # every phase writes flash, so every phase was cut
    print(f"\n{scenario}: cut points per phase (x2: whole and torn step): {dict(per_phase)}; "
          f"{sum(tried.values())} power cuts, each followed by two boots")
    # without a cut the scenario ends on the image it should
    copy_flash(src, tmp_path / "full.flash")
    u = Unit(tmp_path / "full.flash")
    u.boot()
    for _, run in phases:
        run(u)
    assert Unit(tmp_path / "full.flash").boot().image.sha256 == (old_sha if scenario == "revert" else new_sha)
