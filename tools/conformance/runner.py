"""Run every registered check against one device and collect the results."""
from __future__ import annotations

import time
import traceback
from typing import Callable

from stereocam.protocol.errors import StereoCamError

from . import checks  # noqa: F401 - importing the check modules registers them, in order
from .context import Context
from .registry import CHECKS, Family
from .results import CheckFailed, CheckResult, CheckSkipped, Outcome, SuiteResult
from .wire import WireSession

OnResult = Callable[[CheckResult], None]


def run_suite(url: str, timeout: float = 1.0, on_result: OnResult | None = None,
              only: Callable[[str], bool] | None = None) -> SuiteResult:
    """Judge the device at ``url``; ``timeout`` is the reply deadline the device is held to
    (SPEC §7: well inside 1 s). ``on_result`` sees each result as it is made; ``only`` filters
    checks by name. The device is left stopped, with its configuration as found."""
    t0 = time.monotonic()
    suite = SuiteResult(url)

    def record(result: CheckResult) -> None:
        suite.results.append(result)
        if on_result is not None:
            on_result(result)

    session = WireSession.open(url, timeout)
    try:
        ctx = Context.connect(url, session)
    except (StereoCamError, TimeoutError) as exc:
        session.close()
        record(CheckResult("identity.connect", "identity", Outcome.FAIL,
                           f"GET_INFO / STOP / GET_CONFIG failed: {exc}", time.monotonic() - t0))
        suite.duration_s = time.monotonic() - t0
        return suite
    try:
        suite.device = ctx.device_dict()
        _run_all(ctx, record, only or (lambda name: True))
        record(_judge("session.restored", ctx, _restored))
    finally:
        ctx.s.close()
        suite.duration_s = time.monotonic() - t0
    return suite


def _run_all(ctx: Context, record: OnResult, only: Callable[[str], bool]) -> None:
    dead: str | None = None
    for chk in CHECKS:
        if isinstance(chk, Family):
            try:
                members = [(f"{chk.name}.{suffix}", fn) for suffix, fn in chk.fn(ctx)]
            except CheckSkipped as exc:
                if only(chk.name):
                    record(CheckResult(chk.name, chk.area, Outcome.SKIP, str(exc), 0.0))
                continue
        else:
            members = [(chk.name, chk.fn)]
        for name, fn in members:
            if not only(name):
                continue
            if dead is not None:
                record(CheckResult(name, chk.area, Outcome.FAIL, f"not run: {dead}", 0.0))
                continue
            record(_judge(name, ctx, fn))
            dead = _reset(ctx, name)


def _judge(name: str, ctx: Context, fn: Callable[[Context], object]) -> CheckResult:
    area = name.split(".", 1)[0]
    t0 = time.monotonic()
    try:
        detail, outcome = str(fn(ctx) or "ok"), Outcome.PASS
    except CheckSkipped as exc:
        detail, outcome = str(exc), Outcome.SKIP
    except CheckFailed as exc:
        detail, outcome = str(exc), Outcome.FAIL
    except (StereoCamError, TimeoutError) as exc:
        detail, outcome = f"{type(exc).__name__}: {exc}", Outcome.FAIL
    except Exception as exc:  # noqa: BLE001 - a bug in the suite is reported, never hidden
        where = traceback.extract_tb(exc.__traceback__)[-1]
        detail = f"suite error {type(exc).__name__}: {exc} ({where.filename}:{where.lineno})"
        outcome = Outcome.ERROR
    return CheckResult(name, area, outcome, detail, time.monotonic() - t0)


def _reset(ctx: Context, after: str) -> str | None:
    """Back to the known state, on a new link if the device dropped the old one; if it no longer
    answers, say so (later checks are not run)."""
    for attempt in range(2):
        try:
            if not ctx.s.alive:
                ctx.reconnect()
            ctx.reset()
            return None
        except (StereoCamError, TimeoutError) as exc:
            if attempt:
                return f"the device stopped answering after {after}: {exc}"
            time.sleep(1.0)
    return None


def _restored(ctx: Context) -> str:
    """Left as found: stopped, every parameter back to the value it had before the suite."""
    different = ctx.restore_found()
    if different:
        raise CheckFailed(f"configuration differs from the one found: {different}")
    st = ctx.status()
    if st.streaming:
        raise CheckFailed("the device reports streaming after the final STOP")
    return f"stopped, {len(ctx.found)} parameters as found"
