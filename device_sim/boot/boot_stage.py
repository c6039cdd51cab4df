"""The boot stage: picks the image to run from the boot state and what verifies (SPEC §14.2).

  1. A pending trial (activated, not yet tried) that verifies: record "tried", boot it in trial.
     One that does not verify is dropped (state rewritten without it) and never runs.
  2. A trial already tried and still unconfirmed (the unit rebooted before UPDATE_CONFIRM):
     revert, i.e. drop the trial from the state, and go on with step 3.
  3. The active slot if its image verifies, else the other slot if its image verifies. The active
     (confirmed) image's counter is the floor: a state below it (a unit fresh from the factory) is
     raised to it before the image runs.
  4. Neither: recovery (the boot stage's own update service, always present).
Every state change is one atomic record write (boot_state.py), so a power cut at any step leaves
the old or the new state, and the next boot takes one of these branches again.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

from stereocam.protocol.firmware_image import FirmwareImage, ImageError
from stereocam.protocol.update_messages import BootMode

from .boot_state import BootState, BootStateStore
from .slots import Slots


@dataclass(frozen=True)
class Booted:
    """What the boot stage started: the slot (None in recovery), its image, and the boot's trace."""

    slot: int | None
    mode: BootMode
    image: FirmwareImage | None
    state: BootState
    trace: tuple[str, ...] = field(default=())


class BootStage:
    def __init__(self, slots: Slots, states: BootStateStore):
        self.slots = slots
        self.states = states

    def boot(self, recovery: bool = False) -> Booted:
        """Choose and start an image (``recovery``: the recovery strap is held at power-on)."""
        trace: list[str] = []
        state = self.states.read() or BootState()
        if recovery:
            return Booted(None, BootMode.RECOVERY, None, state, ("recovery requested",))
        if (trial := state.trial) is not None and not state.tried:
            try:
                image = self.slots.verify(trial, state.counter)
            except ImageError as exc:
                trace.append(f"pending slot {'AB'[trial]} refused ({exc}): dropped")
                state = self.states.write(replace(state, trial=None))
            else:
                state = self.states.write(replace(state, tried=True))
                trace.append(f"slot {'AB'[trial]} {image.build.version}: trial boot")
                return Booted(trial, BootMode.TRIAL, image, state, tuple(trace))
        elif state.trial is not None:
            trace.append(f"slot {'AB'[state.trial]} was not confirmed: revert to slot {'AB'[state.active]}")
            state = self.states.write(replace(state, trial=None, tried=False))
        for slot in (state.active, 1 - state.active):
            try:
                image = self.slots.verify(slot, state.counter)
            except ImageError as exc:
                trace.append(f"slot {'AB'[slot]} refused: {exc}")
                continue
            if slot == state.active and image.security_counter > state.counter:
                state = self.states.write(replace(state, counter=image.security_counter))
                trace.append(f"security floor raised to {image.security_counter}")
            trace.append(f"slot {'AB'[slot]} {image.build.version}: boot")
            return Booted(slot, BootMode.NORMAL, image, state, tuple(trace))
        trace.append("no image verifies: recovery")
        return Booted(None, BootMode.RECOVERY, None, state, tuple(trace))
