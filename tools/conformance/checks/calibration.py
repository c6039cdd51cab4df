"""Calibration storage (SPEC §12), where advertised: reads agree, a user record is written and
read back byte for byte, restore brings the factory record back, refusals change nothing, and
the unit is left holding the records it was found with."""
from __future__ import annotations

import dataclasses
import zlib

from stereocam.calibration_io import StoredCalibration, read_calibration, write_calibration
from stereocam.protocol import messages as m
from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.params import TriggerMode

from ..context import Context
from ..registry import check
from ..results import CheckSkipped, expect
from ..wire import describe_nack
from .triggers import FRAME_WAIT_S

SMALL_CHUNK = 100


def _records(ctx: Context) -> dict[str, StoredCalibration | None]:
    return {src: read_calibration(ctx.s.call, src) for src in ("active", "factory", "user")}


def _id(rec: StoredCalibration | None) -> int:
    return rec.calibration_id if rec is not None else 0


def _info_id(ctx: Context) -> int:
    info = ctx.s.call(m.GetInfo())
    assert isinstance(info, m.Info)
    return info.calibration_id


@check("calib.read", "R-12.2-1")
def read(ctx: Context) -> str:
    """Active = user if stored, else factory; INFO names it; small chunks reassemble the same body;
    reading past the end is empty; an unknown source is refused OUT_OF_RANGE."""
    ctx.require(m.Capability.CALIBRATION)
    recs = _records(ctx)
    ctx.memo["calibration_found"] = recs
    active, want = recs["active"], recs["user"] or recs["factory"]
    expect(_id(active) == _id(want) and (active is None or want is not None and active.body == want.body),
           f"active record {_id(active):08x}, expected {_id(want):08x} (user if stored, else factory)")
    expect(_info_id(ctx) == _id(active), f"INFO calibration_id {_info_id(ctx):08x}, active {_id(active):08x}")
    if active is not None:
        body = b""
        while len(body) < len(active.body):
            r = ctx.s.call(m.CalibRead(m.CalibSource.ACTIVE, len(body), SMALL_CHUNK))
            assert isinstance(r, m.CalibData)
            expect(r.offset == len(body) and 0 < len(r.data) <= SMALL_CHUNK,
                   f"CALIB_DATA at {r.offset} with {len(r.data)} bytes for a {SMALL_CHUNK}-byte read at {len(body)}")
            body += r.data
        expect(body == active.body, f"{SMALL_CHUNK}-byte chunks reassemble another body")
        end = ctx.s.call(m.CalibRead(m.CalibSource.ACTIVE, len(body), SMALL_CHUNK))
        expect(isinstance(end, m.CalibData) and not end.data, "a read at the end of the body returned data")
    r = ctx.s.exchange(m.CalibRead(3, 0, SMALL_CHUNK))
    expect(isinstance(r, m.Nack) and r.code == ErrorCode.OUT_OF_RANGE,
           f"CALIB_READ source 3: {describe_nack(r) if isinstance(r, m.Nack) else r!r}, expected OUT_OF_RANGE")
    held = ", ".join(f"{k} {_id(v):08x} gen {v.generation}" for k, v in recs.items() if k != "active" and v) or "none"
    return f"records: {held}; active {_id(active):08x}"


@check("calib.write_restore", "R-12.4-3", "R-12.5-1")
def write_restore(ctx: Context) -> str:
    """A user record written, committed and read back byte for byte, in force (INFO and the next
    capture); restore puts the factory record back in force; then the records found are put back."""
    factory, user, test = _test_calibration(ctx, nudge_px=0.25)
    try:
        written = write_calibration(ctx.s.call, test, "user")  # byte-for-byte read-back and generation check
        expect(written.body == test.to_bytes() and written.source == "user", "user record read back differs")
        if user is not None:
            expect(written.generation == user.generation + 1,
                   f"user generation {written.generation} after {user.generation}, expected +1")
        expect(_info_id(ctx) == written.calibration_id, "INFO does not name the user record just written")
        carried = _next_capture_calibration_id(ctx)
        expect(carried in (None, written.calibration_id),
               f"a capture after the commit carries calibration id {carried:08x}, not {written.calibration_id:08x}")
        restored = ctx.s.call(m.CalibRestore())
        assert isinstance(restored, m.CalibRestored)
        expect((restored.source, restored.calibration_id, restored.generation)
               == (m.CalibSource.FACTORY, factory.calibration_id, factory.generation),
               f"CALIB_RESTORED {restored}, expected the factory record {factory.calibration_id:08x} gen "
               f"{factory.generation}")
        expect(read_calibration(ctx.s.call, "user") is None, "a user record is still stored after CALIB_RESTORE")
        expect(_info_id(ctx) == factory.calibration_id, "INFO does not name the factory record after restore")
    finally:
        left = _leave_as_found(ctx, user)
    expect(left == _id(user or factory), f"the unit holds {left:08x}, it was found holding {_id(user or factory):08x}")
    return (f"user record {written.calibration_id:08x} written and verified, factory restored, "
            f"left with {'the user' if user else 'the factory'} record {left:08x} as found")


def _next_capture_calibration_id(ctx: Context) -> int | None:
    """The calibration id one software-triggered capture carries (None without software trigger)."""
    if not ctx.has(m.Capability.SOFTWARE_TRIGGER) or "trigger_mode" not in ctx.params:
        return None
    ctx.apply(trigger_mode=int(TriggerMode.SOFTWARE))
    ctx.s.captures.clear()
    ctx.s.call(m.Start())
    try:
        r = ctx.s.call(m.Trigger())
        assert isinstance(r, m.Triggered)
        ctx.wait_captures(1, FRAME_WAIT_S)
    finally:
        ctx.stop()
    c = ctx.s.captures.find(r.sequence)
    expect(c is not None, f"no capture for trigger {r.trigger_id} within {FRAME_WAIT_S} s")
    assert c is not None
    ctx.note_captures([c])
    return c.begin.calibration_id


def _leave_as_found(ctx: Context, user: StoredCalibration | None) -> int:
    """Put the user record back if there was one, else make sure none is left; returns INFO's id."""
    if user is not None:
        back = write_calibration(ctx.s.call, StereoCalibration.from_bytes(user.body), "user")
        expect(back.body == user.body, "the original user record could not be written back")
    elif read_calibration(ctx.s.call, "user") is not None:
        ctx.s.call(m.CalibRestore())
    return _info_id(ctx)


@check("calib.refusals", "R-12.3-1", "R-12.4-2")
def refusals(ctx: Context) -> str:
    """Bad staging and commits are refused with the SPEC's codes and store nothing."""
    ctx.require(m.Capability.CALIBRATION)
    before = _records(ctx)
    body = b"\x01" * 16
    cases = [
        (m.CalibWrite(0, 0, b""), ErrorCode.OUT_OF_RANGE, "CALIB_WRITE total 0"),
        (m.CalibWrite(0, 16, body), None, "CALIB_WRITE first chunk"),
        (m.CalibWrite(8, 16, body[:8]), ErrorCode.BAD_STATE, "CALIB_WRITE chunk not continuing the staging"),
        (m.CalibWrite(16, 16, b"\x01"), ErrorCode.OUT_OF_RANGE, "CALIB_WRITE past total"),
        (m.CalibCommit(3, 16, zlib.crc32(body)), ErrorCode.OUT_OF_RANGE, "CALIB_COMMIT target 3"),
        (m.CalibCommit(m.CalibSource.USER, 16, zlib.crc32(body) ^ 1), ErrorCode.BAD_PAYLOAD, "CALIB_COMMIT bad CRC"),
        (m.CalibWrite(0, 16, body), None, "CALIB_WRITE restaging"),
        (m.CalibCommit(m.CalibSource.USER, 16, zlib.crc32(body)), ErrorCode.BAD_PAYLOAD,
         "CALIB_COMMIT of a body that is not a calibration"),
    ]
    for msg, code, what in cases:
        r = ctx.s.exchange(msg)
        if code is None:
            expect(not isinstance(r, m.Nack), f"{what}: {describe_nack(r) if isinstance(r, m.Nack) else r!r}")
        else:
            expect(isinstance(r, m.Nack) and r.code == code,
                   f"{what}: {describe_nack(r) if isinstance(r, m.Nack) else r!r}, expected {code.name}")
    after = _records(ctx)
    expect({k: (_id(v), v and v.generation) for k, v in after.items()}
           == {k: (_id(v), v and v.generation) for k, v in before.items()}, "a refused request changed the records")
    return f"{sum(c is not None for _, c, _ in cases)} bad requests refused with the right codes, records unchanged"


def _test_calibration(ctx: Context, nudge_px: float = 0.5
                      ) -> tuple[StoredCalibration, StoredCalibration | None, StereoCalibration]:
    """The factory record, the user record found, and a usable calibration unlike both (a focal
    length nudged by ``nudge_px``); CheckSkipped without a factory record (a test user record could
    not be removed)."""
    ctx.require(m.Capability.CALIBRATION)
    found = _records(ctx)
    factory, user = found["factory"], found["user"]
    if factory is None:
        raise CheckSkipped("no factory record: a test user record could not be removed again")
    base = (user or factory).calibration
    k = base.K_left.copy()
    k[0, 0] += nudge_px
    return factory, user, dataclasses.replace(base, K_left=k)


@check("calib.generation_after_restore", "R-12.1-1")
def generation_after_restore(ctx: Context) -> str:
    """SPEC §12.1: a user record, CALIB_RESTORE, another user record: the second's generation is
    higher than the first's (generations never repeat, so (id, generation) names one commit)."""
    factory, user, test = _test_calibration(ctx)
    try:
        first = write_calibration(ctx.s.call, test, "user")
        restored = ctx.s.call(m.CalibRestore())
        expect(isinstance(restored, m.CalibRestored), f"CALIB_RESTORE answered {restored!r}")
        second = write_calibration(ctx.s.call, test, "user")
    finally:
        left = _leave_as_found(ctx, user)
    expect(second.generation > first.generation,
           f"user generation {second.generation} after a restore, the invalidated record had {first.generation}: "
           f"the pair ({second.calibration_id:08x}, {second.generation}) can name two commits")
    expect(left == _id(user or factory), f"the unit holds {left:08x}, it was found holding {_id(user or factory):08x}")
    return f"user generation {first.generation}, restore, then {second.generation}"


@check("calib.partial_commit", "R-12.4-1")
def partial_commit(ctx: Context) -> str:
    """SPEC §12.4 step 3: a usable body staged in a staging announced 16 bytes longer, committed with
    the staged length and CRC: refused BAD_PAYLOAD (the staging is incomplete), nothing stored."""
    factory, user, test = _test_calibration(ctx)
    body = test.to_bytes()
    before = _records(ctx)
    try:
        staged = ctx.s.call(m.CalibWrite(0, len(body) + 16, body))
        expect(isinstance(staged, m.CalibWritten) and staged.staged == len(body),
               f"CALIB_WRITE of {len(body)} of {len(body) + 16} bytes answered {staged!r}")
        r = ctx.s.exchange(m.CalibCommit(m.CalibSource.USER, len(body), zlib.crc32(body)))
        after = _records(ctx)
    finally:
        left = _leave_as_found(ctx, user)
    expect(isinstance(r, m.Nack) and r.code == ErrorCode.BAD_PAYLOAD,
           f"CALIB_COMMIT of {len(body)} staged bytes of an announced {len(body) + 16}: "
           f"{describe_nack(r) if isinstance(r, m.Nack) else r!r}, expected BAD_PAYLOAD")
    expect({k: _id(v) for k, v in after.items()} == {k: _id(v) for k, v in before.items()},
           "a refused commit of an incomplete staging changed the records")
    expect(left == _id(user or factory), f"the unit holds {left:08x}, it was found holding {_id(user or factory):08x}")
    return f"commit of {len(body)} of {len(body) + 16} staged bytes refused BAD_PAYLOAD, records unchanged"
