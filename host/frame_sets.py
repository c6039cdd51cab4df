"""Frames from several cameras matched into sets by trigger id (the logic of ``CameraGroup``).

A set is emitted, in trigger-id order, once every camera has either delivered its frame for that
id or moved past it (a camera's frames arrive in order, so a later id means this one will never
come), or once ``deadline`` seconds have passed since the set's first frame arrived. A camera
without its frame is named in ``missing``: a set is never completed with a frame of another
trigger. Pulses no camera captured show as sets missing every camera (up to ``MAX_GAP`` of them in a
row; a longer run is only counted, in ``SetStats.skipped``).

Trigger ids come from devices, so none is trusted to be sane: a frame whose id is more than
``MAX_JUMP`` past the (lower) median of the other cameras' latest ids (for the only camera: past its
own previous one) is refused and its camera named in ``SetStats.implausible``; so is a first frame
that far past the median of the first frames (a liar that spoke first). A jump the whole line
makes (every camera) is followed after one refused frame per camera. Work and memory per frame are
bounded whatever ids arrive.
"""
from __future__ import annotations

import collections
import statistics
from dataclasses import dataclass, field
from typing import Iterable

from .frames import Frame

MAX_PENDING = 256  # sets waiting for frames; beyond this the oldest is emitted as it stands
MAX_GAP = MAX_PENDING  # longest run of uncaptured pulses emitted as empty sets; longer runs are counted
MAX_JUMP = 1 << 16  # a trigger id this far past every other camera's is a lie (9 min of pulses at 120 fps)


@dataclass(frozen=True)
class MatchedSet:
    """One trigger: a frame per camera (by name), and the cameras whose frame did not come."""

    trigger_id: int
    frames: dict[str, Frame]
    missing: tuple[str, ...] = ()

    @property
    def complete(self) -> bool:
        return not self.missing

    @property
    def host_times(self) -> dict[str, float]:
        """Each frame's capture time on the host's monotonic clock (s)."""
        return {name: f.host_time for name, f in self.frames.items()}

    @property
    def skew(self) -> float:
        """Spread of the capture times in this set (s; 0 with fewer than two frames)."""
        t = list(self.host_times.values())
        return max(t) - min(t) if len(t) > 1 else 0.0


@dataclass
class SetStats:
    complete: int = 0
    incomplete: int = 0
    missing: collections.Counter[str] = field(default_factory=collections.Counter)  # by camera
    late: collections.Counter[str] = field(default_factory=collections.Counter)  # frames after their set went
    before_start: int = 0  # frames of triggers before every camera was streaming
    implausible: collections.Counter[str] = field(default_factory=collections.Counter)  # frames refused: id jumped
    skipped: int = 0  # pulses in gaps too long to emit as empty sets


class SetMatcher:
    """Not thread-safe: ``CameraGroup`` calls it under its lock."""

    def __init__(self, names: Iterable[str], deadline: float):
        self.names = tuple(names)
        self.deadline = deadline
        self.stats = SetStats()
        self._pending: dict[int, dict[str, Frame]] = {}
        self._arrived: dict[int, float] = {}  # when each pending set's first frame arrived
        self._first: dict[str, int] = {}  # each camera's first trigger id
        self._last: dict[str, int] = {}  # each camera's latest trigger id
        self._claimed: dict[str, int] = {}  # each camera's latest trigger id, refused ones included
        self._since: float | None = None  # arrival of the very first frame
        self._start: int | None = None  # the first trigger id every camera was expected to capture
        self._emitted: int | None = None  # the last trigger id emitted

    def add(self, name: str, frame: Frame, now: float) -> None:
        tid = frame.trigger_id
        if not self._plausible(name, tid):
            self.stats.implausible[name] += 1
            return
        self._first.setdefault(name, tid)
        self._last[name] = max(self._last.get(name, tid), tid)
        self._since = now if self._since is None else self._since
        if self._emitted is not None and tid <= self._emitted:
            self.stats.late[name] += 1
            return
        self._pending.setdefault(tid, {})[name] = frame
        self._arrived.setdefault(tid, now)

    def _plausible(self, name: str, tid: int) -> bool:
        """Whether ``tid`` is within ``MAX_JUMP`` of the ids the other cameras (or, alone, this one)
        claimed last; records it as this camera's claim either way."""
        others = [t for n, t in self._claimed.items() if n != name]
        reference = _lower_median(others) if others else self._claimed.get(name)
        self._claimed[name] = tid
        return reference is None or tid - reference <= MAX_JUMP

    def pop_ready(self, now: float) -> list[MatchedSet]:
        if self._start is None and not self._find_start(now):
            return []
        out: list[MatchedSet] = []
        while self._pending:
            tid = min(self._pending)
            frames = self._pending[tid]
            settled = all(n in frames or self._last.get(n, tid) > tid for n in self.names)
            if not (settled or now - self._arrived[tid] > self.deadline or len(self._pending) > MAX_PENDING):
                break
            first_gap = tid if self._emitted is None else self._emitted + 1
            if tid - first_gap > MAX_GAP:
                self.stats.skipped += tid - first_gap
            else:
                out.extend(self._emit(gap, {}) for gap in range(first_gap, tid))  # pulses nobody captured
            del self._pending[tid], self._arrived[tid]
            out.append(self._emit(tid, frames))
        return out

    def _find_start(self, now: float) -> bool:
        """Sets begin at the first trigger every camera streamed for (or, if a camera stays silent
        past the deadline, the first any camera did); earlier frames are discarded."""
        if len(self._first) == len(self.names):
            self._drop_implausible_firsts()
            self._start = max(self._first.values())
        elif self._pending and self._since is not None and now - self._since > self.deadline:
            self._start = min(self._pending)
        else:
            return False
        for tid in [t for t in self._pending if t < self._start]:
            self.stats.before_start += len(self._pending.pop(tid))
            del self._arrived[tid]
        return True

    def _drop_implausible_firsts(self) -> None:
        """Refuse the frames of cameras whose first id lies more than MAX_JUMP past the median first id
        delivered (a liar whose frame came before any other camera's, so nothing refused it)."""
        limit = _lower_median(list(self._first.values())) + MAX_JUMP
        liars = {n for n, t in self._first.items() if t > limit}
        for tid in [t for t in self._pending if t > limit]:
            for name in [n for n in self._pending[tid] if n in liars]:
                del self._pending[tid][name]
                self.stats.implausible[name] += 1
            if not self._pending[tid]:
                del self._pending[tid], self._arrived[tid]
        for name in liars:
            self._first[name] = min(self._first.values())
            self._last.pop(name, None)

    def _emit(self, tid: int, frames: dict[str, Frame]) -> MatchedSet:
        missing = tuple(n for n in self.names if n not in frames)
        self._emitted = tid
        if missing:
            self.stats.incomplete += 1
            self.stats.missing.update(missing)
        else:
            self.stats.complete += 1
        return MatchedSet(tid, {n: frames[n] for n in self.names if n in frames}, missing)


def _lower_median(values: list[int]) -> int:
    return sorted(values)[(len(values) - 1) // 2]


def sync_problems(sets: Iterable[MatchedSet], max_skew: float) -> list[str]:
    """Why these sets are not trustworthy synchronised captures (empty: none found).

    Two things are looked for: device timestamps identical across heads (separate units count on
    their own clocks, so identical stamps did not come from them: the false-positive sync), and a
    set whose capture times spread more than ``max_skew`` seconds, naming the camera farthest
    from the others (a head a frame behind shows as one frame period)."""
    problems = []
    for s in sets:
        if len(s.frames) < 2:
            continue
        stamps = [f.device_time_us for f in s.frames.values()]
        if len(set(stamps)) < len(stamps):
            problems.append(f"trigger {s.trigger_id}: identical device timestamps across {', '.join(s.frames)}; "
                            "separate units have their own clocks")
        if s.skew > max_skew:
            times = s.host_times
            mid = statistics.median(times.values())
            name = max(times, key=lambda n: abs(times[n] - mid))
            problems.append(f"trigger {s.trigger_id}: capture times spread {s.skew * 1e6:.0f} µs > "
                            f"{max_skew * 1e6:.0f} µs; {name} is {(times[name] - mid) * 1e3:+.3f} ms from the others")
    return problems
