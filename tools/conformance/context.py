"""What every check gets: the session, the device's identity and found configuration, helpers."""
from __future__ import annotations

import time
from dataclasses import dataclass

from stereocam.protocol import messages as m
from stereocam.protocol.params import BY_ID, BY_NAME, Param

from .budget import budget
from .captures import Capture
from .results import CheckSkipped, expect
from .wire import Reply, WireSession

KEEP_ALIVE_S = 0.5  # how often a waiting check sends HEARTBEAT while streaming (SPEC §9 host rate)
LATE_WINDOW_S = 0.15  # how long the suite listens after STOPPED for capture messages that must not come

CAPABILITY_NAMES = {bit: name for name, bit in vars(m.Capability).items() if name.isupper()}  # the protocol's list


@dataclass
class StreamRun:
    """One START..STOP: the captures seen, the device's STATUS either side, late messages."""

    captures: list[Capture]
    before: m.Status
    after: m.Status
    seconds: float  # host time from STARTED to STOPPED
    late_messages: int  # capture messages received after the STOPPED reply
    sequence_problems: list[str]  # sequence / device time not rising from the run's earlier streams

    def delta(self, counter: str) -> int:
        return self.after.counters.get(counter, 0) - self.before.counters.get(counter, 0)


class Context:
    """The device under test as the suite found it, and the means to drive it."""

    def __init__(self, url: str, session: WireSession, info: m.Info, found: dict[int, int]):
        self.url = url
        self.s = session
        self.reconnects = 0
        self.info = info
        self.found = found  # id -> value, as GET_CONFIG returned it before the suite changed anything
        self.params: dict[str, Param] = {BY_ID[i].name: BY_ID[i] for i in found if i in BY_ID}
        self.last_sequence = 0  # across every stream of the run: sequences never go back (SPEC §8.4)
        self.last_device_time = 0
        self.sequence_log: list[str] = []
        self.memo: dict[str, object] = {}  # recordings several checks judge (e.g. one free-run stream)

    @classmethod
    def connect(cls, url: str, session: WireSession) -> "Context":
        """Identify the device and bring it to a known state (stopped), as a host does on connect."""
        info = session.call(m.GetInfo())
        session.call(m.Stop())
        found = session.call(m.GetConfig())
        assert isinstance(info, m.Info) and isinstance(found, m.Config)
        return cls(url, session, info, dict(found.values))

    def reconnect(self) -> None:
        """After the device dropped the link (it may drop a silent host): a new link to the same
        unit; breaches the old link saw stay on record."""
        old = self.s
        old.close()
        self.s = WireSession.open(self.url, old.timeout)
        self.s.violations = old.violations
        self.reconnects += 1
        info = self.s.call(m.GetInfo())
        assert isinstance(info, m.Info)
        expect(info.serial == self.info.serial, f"{self.url} reopened as serial {info.serial}, not {self.info.serial}")

    def device_dict(self) -> dict[str, object]:
        i = self.info
        return {"model": i.model, "serial": i.serial, "firmware_version": i.firmware_version,
                "protocol": f"{i.protocol_version[0]}.{i.protocol_version[1]}", "capabilities": f"0x{i.capabilities:x}",
                "max_width": i.max_width, "max_height": i.max_height, "max_payload": i.max_payload}

    # -- applicability ----------------------------------------------------------------------------
    def has(self, capability: int) -> bool:
        """Whether the device has ``capability`` as negotiated (SPEC §11.2: a 1.2 device has SGM)."""
        return bool(self.info.effective_capabilities & capability)

    def require(self, capability: int) -> None:
        if not self.has(capability):
            raise CheckSkipped(f"{CAPABILITY_NAMES[capability]} not advertised in INFO.capabilities")

    def require_params(self, *names: str) -> None:
        missing = [n for n in names if n not in self.params]
        if missing:
            raise CheckSkipped(f"parameter(s) {', '.join(missing)} not advertised in CONFIG")

    # -- configuration ----------------------------------------------------------------------------
    def config(self) -> dict[str, int]:
        """The device's configuration now, by name (parameters this host knows)."""
        r = self.s.call(m.GetConfig())
        assert isinstance(r, m.Config)
        return {BY_ID[k].name: v for k, v in r.values.items() if k in BY_ID}

    def set(self, **values: int) -> m.Message:
        """SET_CONFIG by name; returns CONFIG_APPLIED or the Nack."""
        return self.s.exchange(m.SetConfig({BY_NAME[k].pid: int(v) for k, v in values.items()}))

    def apply(self, **values: int) -> dict[str, int]:
        """SET_CONFIG that must succeed; only values that differ from the current ones are sent."""
        now = self.config()
        change = {k: v for k, v in values.items() if k in self.params and now.get(k) != v}
        if change:
            r = self.s.call(m.SetConfig({BY_NAME[k].pid: int(v) for k, v in change.items()}))
            assert isinstance(r, m.ConfigApplied)
            now = {BY_ID[k].name: v for k, v in r.values.items() if k in BY_ID}
        return now

    def working_config(self) -> dict[str, int]:
        """The known state every check starts from: the table's defaults at a small format."""
        w = min(320, self.info.max_width - self.info.max_width % 16)
        h = min(240, self.info.max_height - self.info.max_height % 8)
        cfg = {p.name: int(p.default) for p in self.params.values()}
        cfg.update(width=w, height=h, num_disparities=32, block_size=11, fps=15, min_disparity=0)
        return {k: v for k, v in cfg.items() if k in self.params}

    def reset(self) -> None:
        """Between checks: stopped, working configuration."""
        self.s.call(m.Stop())
        self.apply(**self.working_config())

    def restore_found(self) -> dict[int, int]:
        """Put back every parameter the suite may have changed; returns the ids still different."""
        self.s.call(m.Stop())
        now = self.s.call(m.GetConfig())
        assert isinstance(now, m.Config)
        change = {k: v for k, v in self.found.items() if now.values.get(k) != v}
        if change:
            self.s.call(m.SetConfig(change))
        after = self.s.call(m.GetConfig())
        assert isinstance(after, m.Config)
        return {k: v for k, v in after.values.items() if self.found.get(k) != v}

    # -- state ----------------------------------------------------------------------------------
    def status(self) -> m.Status:
        r = self.s.call(m.Heartbeat())
        assert isinstance(r, m.Status)
        return r

    def stop(self) -> Reply:
        """STOP; the raw reply (its ``events_before`` marks where the stream must end)."""
        reply = self.s.wait_reply(self.s.send(m.Stop()))
        expect(isinstance(reply.message, m.Stopped), f"STOP answered with {reply.message!r}")
        return reply

    def wait_captures(self, count: int, seconds: float) -> list[Capture]:
        """Keep the link alive until ``count`` captures have ended or the budget of ``seconds``
        (stretched by STEREOCAM_TIME_FACTOR, budget.py) has passed."""
        return self._collect(count, budget(seconds))

    def _collect(self, count: int, seconds: float) -> list[Capture]:
        """Keep the link alive until ``count`` captures have ended or ``seconds`` have passed."""
        deadline = time.monotonic() + seconds
        alive = time.monotonic()
        while True:
            done = [c for c in self.s.captures.snapshot() if c.end is not None]
            now = time.monotonic()
            if len(done) >= count or now >= deadline:
                return done
            if now - alive >= KEEP_ALIVE_S:
                self.status()
                alive = now
            time.sleep(min(deadline - now, 0.02))

    def stream(self, seconds: float, frames: int | None = None) -> StreamRun:
        """START, collect captures for ``seconds`` (or until ``frames`` ended: then ``seconds`` is a
        budget, stretched like every other), STOP, listen for late ones."""
        before = self.status()
        self.s.captures.clear()
        self.s.call(m.Start())
        t0 = time.monotonic()
        self._collect(frames, budget(seconds)) if frames else self._collect(1 << 30, seconds)
        stopped = self.stop()
        t1 = time.monotonic()
        time.sleep(LATE_WINDOW_S)
        after = self.status()
        captures = self.s.captures.snapshot()
        return StreamRun(captures, before, after, t1 - t0, self.s.captures.messages - stopped.events_before,
                         self.note_captures(captures))

    def note_captures(self, captures: list[Capture]) -> list[str]:
        """Every stream's captures pass through here: sequence numbers and device timestamps rise
        strictly across the whole run (SPEC §8.4, §10). Returns (and logs) the breaches."""
        problems = []
        for c in captures:
            b = c.begin
            if b.sequence <= self.last_sequence:
                problems.append(f"sequence {b.sequence} after {self.last_sequence}")
            if b.device_time_us <= self.last_device_time:
                problems.append(f"device_time_us {b.device_time_us} after {self.last_device_time} (sequence {b.sequence})")
            self.last_sequence = max(self.last_sequence, b.sequence)
            self.last_device_time = max(self.last_device_time, b.device_time_us)
        self.sequence_log += problems
        return problems
