"""Configuration: CONFIG, every advertised parameter at and beyond its limits, all-or-nothing updates."""
from __future__ import annotations

from typing import Iterator

from stereocam.protocol import messages as m
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.params import BY_ID, BY_NAME, PARAMS, Param

from .. import spec_rules
from ..context import Context
from ..registry import CheckFn, check, family
from ..results import CheckFailed, expect
from ..wire import describe_nack

UNUSED_PARAM_ID = 0x7FFE  # never assigned


@check("config.get")
def config_lists_every_parameter(ctx: Context) -> str:
    """CONFIG: ascending ids, every value valid on its own, the table's parameters present."""
    ids = list(ctx.found)
    expect(ids == sorted(ids) and len(set(ids)) == len(ids), f"CONFIG ids not strictly ascending: {ids}")
    bad = [f"{BY_ID[i].name}={v}: {BY_ID[i].check(v)}" for i, v in ctx.found.items() if i in BY_ID and BY_ID[i].check(v)]
    expect(not bad, f"current values the table refuses: {bad}")
    missing = [p.name for p in PARAMS if p.pid not in ctx.found and not (p.name == "rectify"
                                                                          and ctx.info.protocol_version < (1, 1))]
    expect(not missing, f"CONFIG lacks parameters of the SPEC table: {missing}")
    unknown = [i for i in ids if i not in BY_ID]
    return f"{len(ids)} parameters" + (f"; ids {unknown} unknown to this host (not probed)" if unknown else "")


@family("config.limits")
def limits(ctx: Context) -> Iterator[tuple[str, CheckFn]]:
    """One check per advertised parameter: its limits accepted, beyond them refused naming it."""
    for name, p in ctx.params.items():
        yield name, _limit_check(p)


def _limit_check(p: Param) -> CheckFn:
    def run(ctx: Context) -> str:
        base = ctx.apply(**spec_rules.roomy_base(ctx.info.max_width, ctx.info.max_height, set(ctx.params)))
        hi = spec_rules.effective_hi(p, ctx.info.max_width, ctx.info.max_height)
        accept, refuse = spec_rules.limit_probes(p, hi)
        for value in accept:
            if (p.name, value) in spec_rules.optional_values(ctx.info.capabilities):
                _accepted_or_refused(ctx, p, value, base)
            else:
                _expect_outcome(ctx, p, value, base)
        for value, why in refuse:
            _expect_refused(ctx, p, value, ErrorCode.OUT_OF_RANGE, why)
        return f"{' and '.join(map(str, accept))} accepted; {len(refuse)} values beyond refused OUT_OF_RANGE"
    return run


def _expect_outcome(ctx: Context, p: Param, value: int, base: dict[str, int]) -> None:
    """A value within the table: accepted, unless a §5.2 rule forbids it with this base."""
    refusal = spec_rules.cross_refusal({**base, p.name: value}, {p.name})
    if refusal is not None:
        _expect_refused(ctx, p, value, ErrorCode.OUT_OF_RANGE, str(refusal), refusal.param_id)
        return
    r = ctx.set(**{p.name: value})
    if isinstance(r, m.Nack):
        raise CheckFailed(f"{p.name}={value} (within {p.lo}..{p.hi}) refused: {describe_nack(r)}")
    assert isinstance(r, m.ConfigApplied)
    expect(r.values.get(p.pid) == value, f"{p.name}={value} accepted but CONFIG_APPLIED holds {r.values.get(p.pid)}")
    now = ctx.config()
    expect(now.get(p.name) == value, f"{p.name}={value} accepted but GET_CONFIG reads {now.get(p.name)}")
    expect({BY_ID[k].name: v for k, v in r.values.items() if k in BY_ID} == now,
           "CONFIG_APPLIED differs from the GET_CONFIG that follows")
    ctx.apply(**{p.name: base[p.name]})


def _accepted_or_refused(ctx: Context, p: Param, value: int, base: dict[str, int]) -> None:
    """A value a device may lack (its capability not advertised): accepted, or refused OUT_OF_RANGE."""
    before = ctx.config()
    r = ctx.set(**{p.name: value})
    if isinstance(r, m.Nack):
        expect(r.code == ErrorCode.OUT_OF_RANGE and r.param_id == p.pid,
               f"{p.name}={value} (capability not advertised): {describe_nack(r)}, expected OUT_OF_RANGE or accepted")
        expect(ctx.config() == before, f"{p.name}={value} refused but the configuration changed")
    else:
        ctx.apply(**{p.name: base[p.name]})


def _expect_refused(ctx: Context, p: Param, value: int, code: ErrorCode, why: str, blamed: int | None = None) -> None:
    """SET_CONFIG ``p``=``value`` must be NACKed ``code`` naming ``blamed`` (default ``p``); config unchanged."""
    blamed = p.pid if blamed is None else blamed
    before = ctx.config()
    r = ctx.set(**{p.name: value})
    expect(isinstance(r, m.Nack), f"{p.name}={value} ({why}) accepted, expected NACK {code.name}")
    assert isinstance(r, m.Nack)
    expect(r.code == code and r.param_id == blamed,
           f"{p.name}={value} ({why}): {describe_nack(r)}, expected {code.name} naming param {blamed}")
    after = ctx.config()
    expect(after == before, f"{p.name}={value} refused but the configuration changed: "
                            f"{ {k: (before.get(k), v) for k, v in after.items() if before.get(k) != v} }")


@check("config.unknown_param")
def unknown_param(ctx: Context) -> str:
    """An id the device does not have: NACK UNKNOWN_PARAM naming that id; nothing changes."""
    before = ctx.config()
    gain = BY_NAME["gain"]
    update = {gain.pid: gain.hi if before.get("gain") != gain.hi else gain.lo} if "gain" in ctx.params else {}
    update[UNUSED_PARAM_ID] = 1
    r = ctx.s.exchange(m.SetConfig(update))
    expect(isinstance(r, m.Nack) and r.code == ErrorCode.UNKNOWN_PARAM and r.param_id == UNUSED_PARAM_ID,
           f"SET_CONFIG of id {UNUSED_PARAM_ID}: {describe_nack(r) if isinstance(r, m.Nack) else r!r}")
    expect(ctx.config() == before, "a refused SET_CONFIG changed the configuration")
    return f"id {UNUSED_PARAM_ID} NACKed UNKNOWN_PARAM, the valid entry beside it not applied"


@check("config.all_or_nothing")
def all_or_nothing(ctx: Context) -> str:
    """One bad entry refuses the whole update, whatever its position; an empty update changes nothing."""
    ctx.require_params("gain", "fps")
    before = ctx.config()
    new_gain = BY_NAME["gain"].lo + 1 if before["gain"] != BY_NAME["gain"].lo + 1 else BY_NAME["gain"].lo
    for update in ({BY_NAME["gain"].pid: new_gain, BY_NAME["fps"].pid: 0},
                   {BY_NAME["fps"].pid: 0, BY_NAME["gain"].pid: new_gain}):
        r = ctx.s.exchange(m.SetConfig(update))
        expect(isinstance(r, m.Nack) and r.code == ErrorCode.OUT_OF_RANGE and r.param_id == BY_NAME["fps"].pid,
               f"gain={new_gain} with fps=0: {describe_nack(r) if isinstance(r, m.Nack) else r!r}, expected "
               "OUT_OF_RANGE naming fps")
        expect(ctx.config() == before, "gain applied although fps=0 in the same request was refused")
    r = ctx.s.exchange(m.SetConfig({}))
    expect(isinstance(r, m.ConfigApplied), f"empty SET_CONFIG answered {r!r}")
    assert isinstance(r, m.ConfigApplied)
    expect(r.values == ctx.s.call(m.GetConfig()).values, "empty SET_CONFIG: CONFIG_APPLIED differs from CONFIG")
    payload = b"\x02\x00" + _entry("gain", new_gain) + _entry("gain", before["gain"])  # a dict cannot hold this
    dup = ctx.s.wait_reply(ctx.s.send_frame(m.MsgType.SET_CONFIG, payload)).message
    expect(isinstance(dup, m.ConfigApplied) and ctx.config()["gain"] == before["gain"],
           "an id given twice: the last value must be used")
    return "a bad entry first or last refuses the whole update; empty update = CONFIG; duplicate id: last wins"


def _entry(name: str, value: int) -> bytes:
    return BY_NAME[name].pid.to_bytes(2, "little") + value.to_bytes(4, "little", signed=True)


@check("config.live_while_streaming")
def live_while_streaming(ctx: Context) -> str:
    """While streaming: a non-live parameter change is NACKed BAD_STATE naming it, its current value
    is accepted, a live parameter changes."""
    ctx.require_params("width", "gain")
    before = ctx.config()
    ctx.s.call(m.Start())
    try:
        width = BY_NAME["width"]
        other = before["width"] - width.step if before["width"] - width.step >= width.lo else before["width"] + width.step
        r = ctx.set(width=other)
        expect(isinstance(r, m.Nack) and r.code == ErrorCode.BAD_STATE and r.param_id == width.pid,
               f"width change while streaming: {describe_nack(r) if isinstance(r, m.Nack) else 'accepted'}, "
               "expected BAD_STATE naming width")
        r = ctx.set(width=before["width"])
        expect(isinstance(r, m.ConfigApplied), f"width unchanged while streaming refused: {r!r}")
        gain = before["gain"] + 1 if before["gain"] < BY_NAME["gain"].hi else before["gain"] - 1
        r = ctx.set(gain=gain)
        expect(isinstance(r, m.ConfigApplied) and r.values[BY_NAME["gain"].pid] == gain,
               f"live gain change while streaming: {r!r}")
    finally:
        ctx.stop()
    return "width (not live) refused BAD_STATE, same width accepted, gain (live) applied"
