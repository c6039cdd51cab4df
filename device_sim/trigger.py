"""The external trigger line: one wire shared by several heads, pulsed by a master.

A pulse carries its trigger id (the line's pulse number) and the host-monotonic instant of its
edge: on a real wire every head sees the edge at once, so however late a simulated head learns of
it (another thread, another process), it exposes relative to that instant. Each head's trigger
input adds its own latency (``TriggerInput``). ``TriggerMaster`` drives a line at a frame rate,
timed by one unit's crystal; ``TriggerOutput`` is a unit's own connector driving it (SPEC §5.1
``trigger_output``). ``SharedTriggerLine`` (shared_line.py) is the same line across
processes.
"""
from __future__ import annotations

import collections
import random
import re
import threading
import weakref
from typing import Callable, Protocol

from stereocam.protocol.errors import ConfigError

from .clock import REAL_CLOCK, Clock, UnitClock

OnPulse = Callable[[int, float], None]  # (trigger id, host monotonic instant of the edge)
LATENCY_RANGE_S = (2e-6, 8e-6)  # exposure start after the edge, fixed per unit
LATENCY_JITTER_S = 0.3e-6


class Line(Protocol):
    def attach(self, on_pulse: OnPulse) -> None: ...
    def detach(self, on_pulse: OnPulse) -> None: ...
    def pulse(self, instant: float | None = None) -> int: ...


class TriggerLine:
    """In-process: every pulse reaches every head attached to the line with the same trigger id
    (a pulse without an instant is stamped on ``timebase``)."""

    def __init__(self, timebase: Clock = REAL_CLOCK) -> None:
        self._timebase = timebase
        self._lock = threading.Lock()
        self._heads: list[OnPulse] = []
        self.pulses = 0

    def attach(self, on_pulse: OnPulse) -> None:
        with self._lock:
            self._heads.append(on_pulse)

    def detach(self, on_pulse: OnPulse) -> None:
        with self._lock:
            if on_pulse in self._heads:
                self._heads.remove(on_pulse)

    def pulse(self, instant: float | None = None) -> int:
        """Raise the line once (at ``instant``, host monotonic; default now); returns the trigger id."""
        instant = self._timebase.monotonic() if instant is None else instant
        with self._lock:
            self.pulses += 1
            tid = self.pulses
            heads = list(self._heads)
        for head in heads:
            head(tid, instant)
        return tid

    def close(self) -> None:
        with self._lock:
            self._heads.clear()


LINE_NAME = re.compile(r"[A-Za-z0-9_.-]{1,40}")
"""What a trigger line may be called (``sim://?line=NAME``, ``stereocam sim --trigger-line NAME``)."""
_named: "weakref.WeakValueDictionary[str, TriggerLine]" = weakref.WeakValueDictionary()
_named_lock = threading.Lock()


def check_line_name(name: str) -> str:
    """``name`` if it is a valid line name, else ConfigError naming it."""
    if not LINE_NAME.fullmatch(name):
        raise ConfigError(f"trigger line name must be 1-40 of [A-Za-z0-9_.-], got {name!r}")
    return name


def named_line(name: str) -> TriggerLine:
    """The in-process line called ``name`` (``sim://?line=NAME``): every head opened with that name
    is wired to it, for as long as one of them lives."""
    with _named_lock:
        line = _named.get(check_line_name(name))
        if line is None:
            line = _named[name] = TriggerLine()
        return line


class TriggerInput:
    """One unit's trigger input: the exposure starts a few µs (per unit, from its seed) after the edge.

    Two simulator faults: ``miss_next`` — the unit misses that many coming edges (no exposure; their
    ids are appended to ``missed``); ``delay_frames`` — it latches each pulse's id but exposes on
    a later pulse, so its frames carry the right id and the wrong instant (a head a frame behind);
    ``id_offset`` — it adds this to every id it latches (a head lying about trigger ids).
    """

    def __init__(self, seed: int, expose: OnPulse):
        rnd = random.Random(seed ^ 0x7A1C)
        self.latency_s = rnd.uniform(*LATENCY_RANGE_S)
        self.delay_frames = 0
        self.miss_next = 0
        self.id_offset = 0
        self.missed: list[int] = []
        self._expose = expose
        self._noise = random.Random(seed ^ 0x7A1D)
        self._held: collections.deque[int] = collections.deque()

    def on_pulse(self, trigger_id: int, instant: float) -> None:
        if self.miss_next > 0:
            self.miss_next -= 1
            self.missed.append(trigger_id)
            return
        trigger_id += self.id_offset
        at = instant + self.latency_s + self._noise.gauss(0.0, LATENCY_JITTER_S)
        if self.delay_frames:
            self._held.append(trigger_id)
            if len(self._held) <= self.delay_frames:
                return
            trigger_id = self._held.popleft()
        else:
            self._held.clear()
        self._expose(trigger_id, at)


class TriggerMaster:
    """Pulses ``line`` at ``fps`` until closed, the period counted on ``clock`` (the master unit's
    crystal, on its time base; None: the host's, on ``timebase``). Each pulse carries its scheduled
    instant, not the (later) moment this thread got to send it. ``fps`` may be a function, read for
    every period (a unit's frame rate is a live parameter)."""

    def __init__(self, line: Line, fps: float | Callable[[], float], clock: UnitClock | None = None,
                 timebase: Clock = REAL_CLOCK):
        rate = fps if callable(fps) else (lambda: fps)
        if not rate() > 0:
            raise ValueError(f"trigger master fps must be > 0, got {rate()}")
        self.line = line
        self._rate = rate
        self._clock = clock
        self._timebase = clock.timebase if clock is not None else timebase
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="trigger-master", daemon=True)
        self._thread.start()

    @property
    def period(self) -> float:
        nominal = 1.0 / self._rate()
        return self._clock.host_period(nominal) if self._clock is not None else nominal

    def _run(self) -> None:
        t = self._timebase.monotonic() + self.period
        while not self._timebase.wait(self._stop, t - self._timebase.monotonic()):
            self.line.pulse(t)
            t += self.period  # a starved thread catches up: every edge happened, each at its instant

    def close(self) -> None:
        self._stop.set()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout=2)

    def __enter__(self) -> "TriggerMaster":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class TriggerOutput:
    """A unit's trigger output (SPEC §5.1 ``trigger_output``): while its stream runs with the
    output on, it is the line's master, pulsing at its ``fps`` timed by its own crystal. Its own
    trigger input hears the line like every other head's, so it captures on its own pulses."""

    def __init__(self, line: Line, clock: UnitClock, fps: Callable[[], float]):
        self.line = line
        self._clock = clock
        self._fps = fps
        self._lock = threading.Lock()
        self._master: TriggerMaster | None = None

    @property
    def driving(self) -> bool:
        """Whether the line may still pulse (False only once the master's thread has ended)."""
        return self._master is not None

    def drive(self) -> None:
        """Start pulsing (a no-op while already pulsing)."""
        with self._lock:
            if self._master is None:
                self._master = TriggerMaster(self.line, self._fps, self._clock)

    def release(self) -> None:
        """Stop pulsing: the line is left low once this returns."""
        with self._lock:
            if self._master is not None:
                self._master.close()
                self._master = None
