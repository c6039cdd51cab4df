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


@check("config.get", "R-4.3-3")
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


@family("config.limits", "R-4.1-2", "R-4.3-3", "R-5.1-1", "R-5.1-2")
def limits(ctx: Context) -> Iterator[tuple[str, CheckFn]]:
    """One check per advertised parameter: its limits accepted, beyond them refused naming it."""
    for name, p in ctx.params.items():
        yield name, _limit_check(p)


def _limit_check(p: Param) -> CheckFn:
    def run(ctx: Context) -> str:
        max_w, max_h = ctx.info.stage_limit(m.Stage.BLOCK_MATCHING)  # the roomy base block-matches
        base = ctx.apply(**spec_rules.roomy_base(max_w, max_h, set(ctx.params)))
        hi = spec_rules.effective_hi(p, max_w, max_h)
        accept, refuse = spec_rules.limit_probes(p, hi)
        lacking = spec_rules.optional_values(ctx.info.effective_capabilities)
        outcomes = []
        for value in accept:
            if (p.name, value) in lacking:  # SPEC §5.1 capability-bound value: refused, exactly
                _expect_refused(ctx, p, value, ErrorCode.OUT_OF_RANGE, "its capability is not advertised")
                outcomes.append(f"{value} refused (capability not advertised)")
            else:
                outcomes.append(f"{value} {_expect_outcome(ctx, p, value, base)}")
        for value, why in refuse:
            _expect_refused(ctx, p, value, ErrorCode.OUT_OF_RANGE, why)
        return f"{'; '.join(outcomes)}; {len(refuse)} values beyond refused OUT_OF_RANGE"
    return run


def _expect_outcome(ctx: Context, p: Param, value: int, base: dict[str, int]) -> str:
    """A value within the table: accepted, unless a §5.2 rule forbids it with this base; says which."""
    refusal = spec_rules.cross_refusal({**base, p.name: value}, {p.name}, spec_rules.stage_limits(ctx.info))
    if refusal is not None:
        _expect_refused(ctx, p, value, ErrorCode.OUT_OF_RANGE, str(refusal), refusal.param_id)
        return f"refused as §5.2 demands ({refusal.param})"
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
    return "accepted"


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


@check("config.unknown_param", "R-4.3-2")
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


@check("config.all_or_nothing", "R-4.3-1", "R-4.3-2")
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
    current = ctx.s.call(m.GetConfig())
    assert isinstance(current, m.Config)
    expect(r.values == current.values, "empty SET_CONFIG: CONFIG_APPLIED differs from CONFIG")
    return "a bad entry first or last refuses the whole update; empty update = CONFIG"


def _entries(*pairs: tuple[str, int]) -> bytes:
    """A raw param list, duplicates kept (a dict cannot hold them)."""
    return len(pairs).to_bytes(2, "little") + b"".join(
        BY_NAME[n].pid.to_bytes(2, "little") + v.to_bytes(4, "little", signed=True) for n, v in pairs)


def _set_raw(ctx: Context, *pairs: tuple[str, int]) -> m.Message | None:
    return ctx.s.wait_reply(ctx.s.send_frame(m.MsgType.SET_CONFIG, _entries(*pairs))).message


@check("config.duplicate_id", "R-4.3-1")
def duplicate_id(ctx: Context) -> str:
    """SPEC §4.3: an id given twice is checked at every occurrence and the last value is used; while
    streaming a non-live entry is compared with the value in force before the request."""
    ctx.require_params("gain", "width")
    gain, width = BY_NAME["gain"], BY_NAME["width"]
    before = ctx.config()
    a, b = (gain.lo + 1, gain.lo + 2) if before["gain"] != gain.lo + 2 else (gain.lo + 2, gain.lo + 1)
    r = _set_raw(ctx, ("gain", a), ("gain", b))
    expect(isinstance(r, m.ConfigApplied) and r.values.get(gain.pid) == b and ctx.config()["gain"] == b,
           f"gain={a} then gain={b} in one SET_CONFIG: {describe_nack(r) if isinstance(r, m.Nack) else 'applied'}, "
           f"gain now {ctx.config()['gain']}; the last value must be used")
    r = _set_raw(ctx, ("gain", gain.hi + 1), ("gain", a))
    expect(isinstance(r, m.Nack) and r.code == ErrorCode.OUT_OF_RANGE and r.param_id == gain.pid,
           f"gain={gain.hi + 1} then gain={a}: {describe_nack(r) if isinstance(r, m.Nack) else 'accepted'}, expected "
           "OUT_OF_RANGE naming gain (every occurrence is checked)")
    expect(ctx.config()["gain"] == b, "a refused SET_CONFIG with a duplicate id changed gain")
    now = before["width"]
    other = now - width.step if now - width.step >= width.lo else now + width.step
    ctx.s.call(m.Start())
    try:
        r = _set_raw(ctx, ("width", other), ("width", now))
        expect(isinstance(r, m.Nack) and r.code == ErrorCode.BAD_STATE and r.param_id == width.pid,
               f"while streaming, width={other} then width={now} (in force): "
               f"{describe_nack(r) if isinstance(r, m.Nack) else 'accepted'}, expected BAD_STATE naming width")
        r = _set_raw(ctx, ("width", now), ("width", now))
        expect(isinstance(r, m.ConfigApplied), f"while streaming, width={now} twice (in force): {r!r}")
    finally:
        ctx.stop()
    return (f"gain {a},{b} -> {b}; gain {gain.hi + 1},{a} refused OUT_OF_RANGE; streaming width {other},{now} "
            f"refused BAD_STATE, {now},{now} applied")


@check("config.live_while_streaming", "R-4.3-2")
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
