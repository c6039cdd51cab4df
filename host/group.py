"""``CameraGroup``: several cameras on one external trigger line, frames matched by trigger id.

The group opens every camera, configures them alike (plus per-camera settings), sets
``trigger_mode=external`` on all, makes one of them the trigger master (``trigger_output=1``: it
pulses the line at its ``fps`` while streaming, SPEC §5.1; the others' output off) and starts them,
the master last so that its first pulse finds every head streaming. ``master=None`` when something
outside the group drives the line (a signal generator, a unit not in the group). Every pulse
carries the line's pulse number, which each head puts in its frames' ``trigger_id``; that is what
the group matches on. Each frame's ``host_time`` is its own camera's device timestamp through that
camera's clock map, so the spread of a set measures the sync; ``clock_errors`` says how far each
map is trusted.

    with stereocam.CameraGroup(["socket://10.0.0.2:5000", "socket://10.0.0.3:5000"],
                               config={"fps": 30}, deadline=0.5) as group:
        for s in group:
            if not s.complete:
                print(f"trigger {s.trigger_id}: no frame from {', '.join(s.missing)}")
            for name, frame in s.frames.items():
                use(name, frame, frame.host_time)
"""
from __future__ import annotations

import collections
import numbers
import threading
import time
from typing import Iterator, Mapping, Sequence

from stereocam.protocol import messages as m
from stereocam.protocol.errors import CameraTimeoutError, ConfigError, StereoCamError
from stereocam.protocol.params import TriggerMode

from .arguments import timeout_arg
from .camera import Camera, open as open_camera
from .connection import SYNC_BURST
from .clock import MapError
from .frame_sets import MatchedSet, SetMatcher, SetStats

SETTLE_PERIOD = 0.1  # seconds between time-sync bursts while settling
READY_KEEP = 64  # matched sets waiting for the user; beyond this the oldest are discarded (counted)


class CameraGroup:
    """Several cameras streaming together on one trigger line; iterate for ``MatchedSet``s."""

    def __init__(self, urls: Sequence[str], *, config: Mapping[str, int] | None = None,
                 per_camera: Sequence[Mapping[str, int] | None] | None = None, master: int | None = 0,
                 deadline: float = 0.5, timeout: float = 1.0, settle: float = 1.0, **open_kwargs):
        """``config``: parameters for every camera; ``per_camera``: more for each (same order as
        ``urls``). ``master``: index (in ``urls``) of the camera that drives the trigger line at its
        ``fps``; it must advertise TRIGGER_OUTPUT. None: the line is driven from outside the group
        (every camera's output is then switched off where it has one). ``deadline``: seconds after
        a set's first frame before it is given up as incomplete. ``timeout``: how long iteration
        waits for the next set. ``settle``: seconds of time-sync bursts before streaming, so every
        clock map knows its drift from the first set (without, the first seconds' sets are the
        loosest)."""
        if isinstance(urls, (str, bytes)) or not isinstance(urls, Sequence) or not urls:
            raise ConfigError(f"CameraGroup needs a list of camera URLs, got {urls!r}")
        if config is not None and not isinstance(config, Mapping):
            raise ConfigError(f"config must be a mapping of parameter names to values, got {config!r}")
        if per_camera is not None and (isinstance(per_camera, (str, bytes)) or not isinstance(per_camera, Sequence)
                                       or any(c is not None and not isinstance(c, Mapping) for c in per_camera)):
            raise ConfigError(f"per_camera must be a list of mappings (or None), one per camera, got {per_camera!r}")
        if per_camera is not None and len(per_camera) != len(urls):
            raise ConfigError(f"per_camera has {len(per_camera)} entries for {len(urls)} cameras")
        if master is not None and (isinstance(master, bool) or not isinstance(master, numbers.Integral)
                                   or not 0 <= master < len(urls)):
            raise ConfigError(f"master must be the index of one of the {len(urls)} cameras (0..{len(urls) - 1}) "
                              f"or None, got {master!r}")
        self.master = None if master is None else int(master)
        self.urls = list(urls)
        self.timeout = timeout_arg(timeout)
        self._config = dict(config or {})
        self._per_camera = list(per_camera or [None] * len(urls))
        self._deadline = timeout_arg(deadline, "deadline")
        self._settle = timeout_arg(settle, "settle")
        self._opened = False
        self._open_kwargs = open_kwargs
        self.cameras: dict[str, Camera] = {}
        self._cond = threading.Condition()
        self._ready: collections.deque[MatchedSet] = collections.deque()
        self._matcher: SetMatcher | None = None
        self._errors: dict[str, StereoCamError] = {}
        self._closed = threading.Event()
        self._threads: list[threading.Thread] = []
        self.discarded = 0  # matched sets dropped because the user did not keep up

    # -- lifetime -------------------------------------------------------------------------------
    def open(self) -> "CameraGroup":
        """Open, configure and start every camera; closes what it opened if any step fails. Once:
        a group that was opened (or closed) is not opened again (make a new one)."""
        if self._opened or self._closed.is_set():
            raise StereoCamError("this CameraGroup was already opened; a closed group is not reopened: "
                                 "make a new CameraGroup")
        self._opened = True
        try:
            for i, (url, extra) in enumerate(zip(self.urls, self._per_camera)):
                cam = open_camera(url, self.timeout, **self._open_kwargs)
                info = cam.info()
                name = info.serial if info.serial not in self.cameras else f"{info.serial}#{len(self.cameras)}"
                self.cameras[name] = cam
                values = {**self._config, **(extra or {}), "trigger_mode": int(TriggerMode.EXTERNAL)}
                if info.capabilities & m.Capability.TRIGGER_OUTPUT:
                    values["trigger_output"] = int(i == self.master)
                elif i == self.master:
                    raise ConfigError(f"camera {name} ({url}) cannot drive the trigger line (INFO lacks "
                                      "TRIGGER_OUTPUT): choose another master=, or master=None when the line "
                                      "is driven from outside the group")
                cam.configure(**values)
            self._settle_clocks()
            self._matcher = SetMatcher(self.cameras, self._deadline)
            names = list(self.cameras)
            if self.master is not None:  # the master last: its first pulse finds every head streaming
                names.append(names.pop(self.master))
            for name in names:
                self.cameras[name].start()
        except BaseException:
            self.close()
            raise
        for name, cam in self.cameras.items():
            t = threading.Thread(target=self._collect, args=(name, cam), name=f"group-{name}", daemon=True)
            t.start()
            self._threads.append(t)
        return self

    def _settle_clocks(self) -> None:
        end = time.monotonic() + self._settle
        while time.monotonic() < end:
            for cam in self.cameras.values():
                cam.sync_clock(SYNC_BURST)
            time.sleep(SETTLE_PERIOD)

    def close(self) -> None:
        self._closed.set()
        for t in self._threads:
            t.join(timeout=2)
        for cam in self.cameras.values():
            cam.close()

    def __enter__(self) -> "CameraGroup":
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- frames in ------------------------------------------------------------------------------
    def _collect(self, name: str, cam: Camera) -> None:
        while not self._closed.is_set():
            try:
                frame = cam.get_frame(timeout=0.1)
            except CameraTimeoutError:
                continue
            except StereoCamError as exc:  # the link died: the user's next call raises it
                with self._cond:
                    self._errors[name] = exc
                    self._cond.notify_all()
                return
            with self._cond:
                assert self._matcher is not None
                self._matcher.add(name, frame, time.monotonic())
                self._cond.notify_all()

    # -- sets out -------------------------------------------------------------------------------
    def get_set(self, timeout: float | None = None) -> MatchedSet:
        """The next set, in trigger-id order: complete, or with ``missing`` naming the cameras
        whose frame for that trigger did not come within the deadline. CameraTimeoutError if
        none within ``timeout``; the error of a camera whose link died."""
        timeout = self.timeout if timeout is None else timeout_arg(timeout)
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                if self._matcher is None:
                    raise StereoCamError("CameraGroup is not open (use it as a context manager or call open())")
                for s in self._matcher.pop_ready(time.monotonic()):
                    self._ready.append(s)
                    if len(self._ready) > READY_KEEP:
                        self._ready.popleft()
                        self.discarded += 1
                if self._ready:
                    return self._ready.popleft()
                if self._errors:
                    name, exc = next(iter(self._errors.items()))
                    raise type(exc)(f"camera {name}: {exc}") from exc
                left = deadline - time.monotonic()
                if left <= 0:
                    raise CameraTimeoutError(f"no matched set from {', '.join(self.cameras)} within {timeout:.3g} s")
                self._cond.wait(min(left, self._deadline / 4))

    def __iter__(self) -> Iterator[MatchedSet]:
        """Sets as they come, until none arrives within ``timeout``."""
        while True:
            try:
                yield self.get_set()
            except CameraTimeoutError:
                return

    @property
    def stats(self) -> SetStats:
        """Complete and incomplete sets, missing frames by camera, late frames."""
        return self._matcher.stats if self._matcher is not None else SetStats()

    def clock_errors(self) -> dict[str, MapError]:
        """Each camera's current clock-map error estimate."""
        return {name: cam.clock.error() for name, cam in self.cameras.items()}
