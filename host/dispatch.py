"""Frames to every consumer at once, as python-can's Notifier hands messages to its listeners.

The frame assembler hands each frame to one ``FrameDispatcher``; the dispatcher offers it to every
listener without waiting on any of them. A listener keeps frames in its own bounded queue under its
own drop policy and counts its own drops, so a slow one (a callback, a recorder on a slow disk) loses
frames itself and never holds up the others (the user's ``get_frame``, the viewer's newest frame).
"""
from __future__ import annotations

import collections
import enum
import logging
import threading
import time
from typing import Protocol

from stereocam.protocol.errors import ConfigError

from .arguments import count_arg
from .frame_types import Frame

_log = logging.getLogger(__name__)


class DropPolicy(enum.Enum):
    """What a full listener queue does with one more frame."""

    DROP_OLDEST = "drop-oldest"  # the oldest queued frame goes: the consumer sees the latest ones
    DROP_NEWEST = "drop-newest"  # the new frame goes: what is queued stays, in order (a recorder)
    KEEP_NEWEST = "keep-newest"  # a one-frame slot: each frame replaces the last (a live view)


class Listener(Protocol):
    """Anything that takes frames from a dispatcher; ``put`` must return at once, never wait."""

    def put(self, frame: Frame) -> None: ...


class FrameQueue:
    """A listener that keeps frames for a consumer thread to ``get``: bounded, with a drop policy
    and its own count of the frames it dropped."""

    def __init__(self, name: str, maxsize: int = 8, policy: DropPolicy = DropPolicy.DROP_OLDEST):
        if not isinstance(policy, DropPolicy):
            raise ConfigError(f"a drop policy is a DropPolicy, got {policy!r}")
        self.name = name
        self.policy = policy
        self.maxsize = 1 if policy is DropPolicy.KEEP_NEWEST else count_arg(maxsize, "maxsize", 1)
        self._frames: collections.deque[Frame] = collections.deque()
        self._cond = threading.Condition()
        self._dropped = 0

    def put(self, frame: Frame) -> None:
        with self._cond:
            if len(self._frames) >= self.maxsize:
                self._dropped += 1
                if self.policy is DropPolicy.DROP_NEWEST:
                    _log.debug("%s: frame %d dropped, the queue is full", self.name, frame.sequence)
                    return
                old = self._frames.popleft()
                _log.debug("%s: frame %d discarded for a newer one", self.name, old.sequence)
            self._frames.append(frame)
            self._cond.notify()

    def get(self, timeout: float) -> Frame | None:
        """The oldest queued frame, waiting up to ``timeout`` seconds (0: at once); None if none came."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while not self._frames:
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._cond.wait(left)
            return self._frames.popleft()

    def clear(self) -> None:
        """Forget the queued frames (not counted as drops: nobody wanted them)."""
        with self._cond:
            self._frames.clear()

    @property
    def dropped(self) -> int:
        """Frames this listener lost to its policy (a KEEP_NEWEST slot: frames replaced unseen)."""
        with self._cond:
            return self._dropped

    def __len__(self) -> int:
        with self._cond:
            return len(self._frames)


class FrameDispatcher:
    """Offers every frame to every listener; listeners come and go from any thread."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._listeners: tuple[Listener, ...] = ()

    def add(self, listener: Listener) -> None:
        with self._lock:
            if listener not in self._listeners:
                self._listeners += (listener,)

    def remove(self, listener: Listener) -> None:
        """Stop offering frames to ``listener`` (nothing happens if it was not added)."""
        with self._lock:
            self._listeners = tuple(x for x in self._listeners if x is not listener)

    def __contains__(self, listener: object) -> bool:
        return listener in self._listeners

    def dispatch(self, frame: Frame) -> None:
        """Offer ``frame`` to every listener; one that raises is logged and the others still get it."""
        for listener in self._listeners:
            try:
                listener.put(frame)
            except Exception as exc:
                _log.error("frame listener %r failed on frame %d: %r", listener, frame.sequence, exc, exc_info=exc)
