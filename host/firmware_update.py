"""Updating a camera's firmware (protocol SPEC §14): transfer (resumable), verify, activate, wait for
the unit to reboot, reconnect by serial, check it runs the new image, confirm.

Success is reported only after the unit runs the new build's version and reports, from the slot
it booted, the hash of the image that was sent; anything else raises and leaves the image
unconfirmed, so the unit reverts to the previous one at its next boot.
"""
from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass
from typing import Callable

from stereocam.protocol import messages as m
from stereocam.protocol.errors import (DeviceError, DisconnectedError, ErrorCode, StereoCamError,
                                       VerificationError)
from stereocam.protocol.firmware_image import ImageFault, inspect_image

Progress = Callable[[int, int], None]


class FirmwareUpdateError(StereoCamError):
    """The update did not (or could not) complete; the unit keeps running a valid image."""


class ImageRefusedError(FirmwareUpdateError):
    """The unit refused the image; ``fault`` says why (unsigned, tampered, wrong key, ...)."""

    def __init__(self, fault: ImageFault | None, message: str):
        super().__init__(message)
        self.fault = fault


@dataclass(frozen=True)
class SlotStatus:
    slot: str  # "A" or "B"
    state: m.SlotState
    version: str
    security_counter: int
    sha256: str  # hex, read back from the slot by the unit

    @property
    def confirmed(self) -> bool:
        return self.state == m.SlotState.ACTIVE


@dataclass(frozen=True)
class FirmwareStatus:
    running: str  # "A", "B" or "recovery"
    mode: m.BootMode
    security_counter: int
    transfer: tuple[int, int]  # (received, size) of a transfer in progress; size 0: none
    slots: tuple[SlotStatus, ...]


@dataclass(frozen=True)
class UpdateResult:
    version: str
    slot: str
    sha256: str
    resumed_from: int  # bytes the unit already held when this transfer began
    seconds: float


def status(request) -> FirmwareStatus:
    r = request(m.UpdateStatus())
    slots = tuple(SlotStatus("AB"[s.slot], m.SlotState(s.state), s.version, s.security_counter, s.sha256.hex())
                  for s in r.slots)
    running = "recovery" if r.running_slot == 0xFF else "AB"[r.running_slot]
    return FirmwareStatus(running, m.BootMode(r.boot_mode), r.security_counter, (r.received, r.size), slots)


def _refused(exc: DeviceError) -> FirmwareUpdateError:
    if exc.code != ErrorCode.IMAGE_REJECTED:
        return FirmwareUpdateError(str(exc))
    name = exc.device_message.split(":", 1)[0].upper()
    return ImageRefusedError(ImageFault[name] if name in ImageFault.__members__ else None, str(exc))


def transfer(request, image: bytes, progress: Progress | None = None, replace: bool = False) -> tuple[int, int]:
    """Send ``image`` to the slot that is not running, resuming where the unit's bytes end, and
    verify it there; returns (slot, bytes the unit held before)."""
    digest = hashlib.sha256(image).digest()
    try:
        begun = request(m.UpdateBegin(len(image), digest, m.BEGIN_REPLACE if replace else 0))
        offset = start = begun.received
        while offset < len(image):
            r = request(m.UpdateData(offset, image[offset:offset + m.MAX_UPDATE_CHUNK]))
            offset = r.received
            if progress is not None:
                progress(offset, len(image))
        verified = request(m.UpdateVerify())
    except DeviceError as exc:
        raise _refused(exc) from exc
    if verified.info.sha256 != digest:
        raise VerificationError(f"slot {'AB'[verified.info.slot]} holds {verified.info.sha256.hex()}, "
                                f"sent {digest.hex()}")
    return verified.info.slot, start


def update(cam, image: bytes, *, progress: Progress | None = None, replace: bool = False,
           reboot_timeout: float = 30.0) -> UpdateResult:
    """Install ``image`` on the camera ``cam`` (a stereocam.Camera) and confirm it once it runs.
    A unit already running this image on trial (an update cut after its reboot) is checked and
    confirmed without a new transfer; one running another image on trial is refused."""
    t0 = time.monotonic()
    expected = inspect_image(image)  # a malformed file fails here, before the unit is touched
    if not cam.info().capabilities & m.Capability.FIRMWARE_UPDATE:
        raise FirmwareUpdateError(f"{cam.url} does not offer firmware updates (no FIRMWARE_UPDATE capability)")
    before = status(cam.request)
    trial = next((s for s in before.slots if s.slot == before.running), None)
    if before.mode == m.BootMode.TRIAL and trial is not None and trial.sha256 == expected.sha256.hex():
        slot, start = "AB".index(trial.slot), len(image)  # finish the update that was cut after its reboot
    elif before.mode == m.BootMode.TRIAL:
        raise FirmwareUpdateError(f"{cam.url} runs {trial.version if trial else '?'} on trial, from an update not "
                                  "confirmed yet: finish that update, or reset the unit to revert it")
    else:
        slot, start = transfer(cam.request, image, progress, replace)
        cam.request(m.UpdateActivate())
        await_reboot(cam, reboot_timeout)
    info = cam.info()
    st = status(cam.request)
    running = next((s for s in st.slots if s.slot == st.running), None)
    if info.firmware_version != expected.build.version or running is None or running.slot != "AB"[slot]:
        raise FirmwareUpdateError(f"after the reboot the unit runs {info.firmware_version} from {st.running}, "
                                  f"not {expected.build.version} from slot {'AB'[slot]}; the new image was not booted")
    if running.sha256 != expected.sha256.hex():
        raise VerificationError(f"slot {running.slot} reads back hash {running.sha256}, sent {expected.sha256.hex()}")
    cam.status()  # health check: the new firmware answers its heartbeat and its configuration
    cam.config()
    try:
        confirmed = cam.request(m.UpdateConfirm())
    except DeviceError as exc:
        raise FirmwareUpdateError(f"the unit did not confirm the new image: {exc}") from exc
    if confirmed.info.state != m.SlotState.ACTIVE:
        raise FirmwareUpdateError(f"slot {running.slot} is {m.SlotState(confirmed.info.state).name} after confirm")
    return UpdateResult(info.firmware_version, running.slot, running.sha256, start, time.monotonic() - t0)


def await_reboot(cam, timeout: float) -> None:
    """Wait for the link to drop (the unit resets), then reconnect to the same serial."""
    deadline = time.monotonic() + timeout
    while cam.alive:
        if time.monotonic() > deadline:
            raise FirmwareUpdateError(f"{cam.url} did not reboot within {timeout:.3g} s of UPDATE_ACTIVATE")
        time.sleep(0.01)
    try:
        cam.reconnect(timeout=max(deadline - time.monotonic(), 1.0), expected=True)  # the reboot it asked for
    except DisconnectedError as exc:
        raise FirmwareUpdateError(f"the unit did not come back after the reboot: {exc}") from exc
