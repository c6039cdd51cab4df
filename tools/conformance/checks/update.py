"""Firmware update (SPEC §14, protocol 1.2): the slot report agrees with INFO, and requests the unit
cannot act on are refused with the SPEC's codes without changing a slot or starting a transfer.
Nothing here writes an image: a conformance run never changes what a unit boots."""
from __future__ import annotations

from stereocam.protocol import messages as m
from stereocam.protocol.errors import ErrorCode

from ..context import Context
from ..registry import check
from ..results import CheckSkipped, expect
from ..wire import describe_nack

RECOVERY_SLOT = 0xFF


def _state(ctx: Context) -> m.UpdateState:
    r = ctx.s.call(m.UpdateStatus())
    assert isinstance(r, m.UpdateState)
    return r


@check("update.status", "R-14.3-1")
def update_status(ctx: Context) -> str:
    """UPDATE_STATUS: the running slot holds the version INFO reports, in the state its boot mode says."""
    ctx.require(m.Capability.FIRMWARE_UPDATE)
    st = _state(ctx)
    expect(st.running_slot in (0, 1, RECOVERY_SLOT), f"running_slot {st.running_slot}: 0, 1 or 0xFF expected")
    expect(st.boot_mode in {int(b) for b in m.BootMode}, f"boot_mode {st.boot_mode} is not a BootMode")
    expect(len({s.slot for s in st.slots}) == len(st.slots) >= 2, f"slots {[s.slot for s in st.slots]}: two or more, "
                                                                   "each once")
    if st.running_slot == RECOVERY_SLOT:
        expect(st.boot_mode == m.BootMode.RECOVERY, f"running_slot 0xFF with boot_mode {st.boot_mode}")
        return f"recovery; slots {[m.SlotState(s.state).name for s in st.slots]}"
    run = next((s for s in st.slots if s.slot == st.running_slot), None)
    expect(run is not None, f"no SlotInfo for the running slot {st.running_slot}")
    assert run is not None
    expect(run.version == ctx.info.firmware_version,
           f"running slot reports version {run.version!r}, INFO {ctx.info.firmware_version!r}")
    want = m.SlotState.TRIAL if st.boot_mode == m.BootMode.TRIAL else m.SlotState.ACTIVE
    expect(run.state == want, f"running slot {m.SlotState(run.state).name} with boot mode "
                              f"{m.BootMode(st.boot_mode).name}; {want.name} expected")
    expect(any(run.sha256), "the running slot reports no image hash")
    return (f"running slot {'AB'[st.running_slot]} {run.version} ({m.BootMode(st.boot_mode).name.lower()}), "
            f"minimum security counter {st.security_counter}")


@check("update.refusals", "R-14.3-1")
def update_refusals(ctx: Context) -> str:
    """An image size no slot can hold, and VERIFY / ACTIVATE with no transfer, are refused with the
    SPEC's codes; UPDATE_STATUS is unchanged after them."""
    ctx.require(m.Capability.FIRMWARE_UPDATE)
    before = _state(ctx)
    if before.size:
        raise CheckSkipped(f"a transfer is in progress on the unit ({before.received} of {before.size} bytes): "
                           "left alone")
    cases = [("UPDATE_BEGIN of 0 bytes", m.UpdateBegin(0, bytes(32)), {ErrorCode.OUT_OF_RANGE, ErrorCode.BAD_STATE}),
             ("UPDATE_BEGIN of 4 GiB", m.UpdateBegin(0xFFFFFFFF, bytes(32)),
              {ErrorCode.OUT_OF_RANGE, ErrorCode.BAD_STATE}),
             ("UPDATE_VERIFY with no transfer", m.UpdateVerify(), {ErrorCode.BAD_STATE}),
             ("UPDATE_ACTIVATE with no transfer", m.UpdateActivate(), {ErrorCode.BAD_STATE})]
    for what, msg, codes in cases:
        r = ctx.s.exchange(msg)
        expect(isinstance(r, m.Nack) and r.code in codes,
               f"{what}: {describe_nack(r) if isinstance(r, m.Nack) else type(r).__name__}, expected "
               f"{' or '.join(sorted(c.name for c in codes))}")
    after = _state(ctx)
    expect(after == before, "a refused update request changed the slots or started a transfer")
    return f"{len(cases)} requests refused with the SPEC's codes, slots unchanged"
