"""``CameraGroup``: several cameras on one external trigger line, frames matched by trigger id.

The group opens every camera, configures them alike (plus per-camera settings), sets
``trigger_mode=external`` on all, makes one of them the trigger master (``trigger_output=1``: it
pulses the line at its ``fps`` while streaming, SPEC §5.1; the others' output off) and starts them,
the master last so that its first pulse finds every head streaming. ``master=None`` when something
outside the group drives the line (a signal generator, a unit not in the group). Every pulse
carries the line's pulse number, which each head puts in its frames' ``trigger_id``; that is what
the group matches on. A head that sees no pulses while the others stream (an unwired head, a cable
out) is named by ``get_set`` (SilentHeadsError) within ``SILENT_PERIODS`` frame periods (at least the
deadline, two heartbeats). Closing the group stops its cameras and puts back every parameter it
changed on them (trigger mode and output included), unless ``keep_config=True``. Each frame's
``host_time`` is its own camera's device timestamp through that camera's clock map, so the spread
of a set measures the sync; ``clock_errors`` says how far each map is trusted.

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
import logging
import numbers
import threading
import time
from typing import Iterator, Mapping, Sequence

from stereocam.protocol import messages as m
from stereocam.protocol.errors import (CameraTimeoutError, ConfigError, SilentHeadsError, StereoCamError,
                                      TransportError)
from stereocam.protocol.params import TriggerMode

from .arguments import flag_arg, timeout_arg
from .camera import Camera, open as open_camera
from .connection import HEARTBEAT_INTERVAL, SYNC_BURST
from .clock import MapError
from .frame_sets import MatchedSet, SetMatcher, SetStats

SETTLE_PERIOD = 0.1  # seconds between time-sync bursts while settling
READY_KEEP = 64  # matched sets waiting for the user; beyond this the oldest are discarded (counted)
SILENT_PERIODS = 5  # frame periods without a frame, while another head streams, before a head is named silent

_log = logging.getLogger(__name__)


class CameraGroup:
    """Several cameras streaming together on one trigger line; iterate for ``MatchedSet``s."""

    def __init__(self, urls: Sequence[str], *, config: Mapping[str, int] | None = None,
                 per_camera: Sequence[Mapping[str, int] | None] | None = None, master: int | None = 0,
                 deadline: float = 0.5, timeout: float = 1.0, settle: float = 1.0, keep_config: bool = False,
                 **open_kwargs):
        """``config``: parameters for every camera; ``per_camera``: more for each (same order as
        ``urls``). ``master``: index (in ``urls``) of the camera that drives the trigger line at its
        ``fps``; it must advertise TRIGGER_OUTPUT. None: the line is driven from outside the group
        (every camera's output is then switched off where it has one). ``deadline``: seconds after
        a set's first frame before it is given up as incomplete. ``timeout``: how long iteration
        waits for the next set. ``settle``: seconds of time-sync bursts before streaming, so every
        clock map knows its drift from the first set (without, the first seconds' sets are the
        loosest); the first ``get_set`` waits this much longer than ``timeout``. ``keep_config``: leave
        the cameras configured as the group set them when it closes (default: put back what it changed)."""
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
        self._keep_config = flag_arg(keep_config, "keep_config")
        self._opened = False
        self._open_kwargs = open_kwargs
        self.cameras: dict[str, Camera] = {}
        self._url_of: dict[str, str] = {}  # camera name -> its URL
        self._found: dict[str, dict[str, int]] = {}  # camera name -> the values the group changed, as found
        self._period = 0.0  # the longest frame period of the group's cameras (s)
        self._started = 0.0  # when the last camera was started (host monotonic)
        self._last_frame: dict[str, float] = {}  # camera name -> when it last showed it heard a pulse
        self._triggers: dict[str, int] = {}  # camera name -> its device's ``triggers`` counter (SPEC §8) seen last
        self._reported: set[str] = set()  # silent heads get_set has named
        self._first_given = False
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
                self._url_of[name] = url
                values = {**self._config, **(extra or {}), "trigger_mode": int(TriggerMode.EXTERNAL)}
                if info.capabilities & m.Capability.TRIGGER_OUTPUT:
                    values["trigger_output"] = int(i == self.master)
                elif i == self.master:
                    raise ConfigError(f"camera {name} ({url}) cannot drive the trigger line (INFO lacks "
                                      "TRIGGER_OUTPUT): choose another master=, or master=None when the line "
                                      "is driven from outside the group")
                found = cam.config()
                self._found[name] = {k: found[k] for k, v in values.items() if k in found and found[k] != v}
                self._period = max(self._period, 1.0 / cam.configure(**values)["fps"])
                self._triggers[name] = cam.status().counters.get("triggers", 0)
            self._settle_clocks()
            self._matcher = SetMatcher(self.cameras, self._deadline)
            names = list(self.cameras)
            if self.master is not None:  # the master last: its first pulse finds every head streaming
                names.append(names.pop(self.master))
            for name in names:
                self.cameras[name].start()
            self._started = time.monotonic()
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
        """Stop every camera (the master first: the line goes quiet), put back what the group changed
        (unless ``keep_config``) and close them. A camera that cannot be reached is logged and closed.
        Idempotent: a second call (or one while another thread closes) does nothing. ``get_set`` calls
        waiting in other threads raise at once (TransportError: closed)."""
        with self._cond:
            if self._closed.is_set():
                return
            self._closed.set()
            self._cond.notify_all()
        for t in self._threads:
            t.join(timeout=2)
        names = list(self.cameras)
        if self.master is not None and self.master < len(names):
            names.insert(0, names.pop(self.master))
        for name in names:
            self._put_back(name, self.cameras[name])
        for cam in self.cameras.values():
            cam.close()

    def _put_back(self, name: str, cam: Camera) -> None:
        try:
            if cam.streaming:
                cam.stop()
            if not self._keep_config and self._found.get(name):
                cam.configure(**self._found[name])
        except StereoCamError as exc:
            _log.warning("camera %s (%s): could not be stopped and put back as found: %s", name,
                         self._url_of.get(name, "?"), exc)

    def __repr__(self) -> str:
        state = "closed" if self._closed.is_set() else "open" if self._opened else "not opened"
        heads = list(self.cameras) or self.urls
        return f"<CameraGroup {', '.join(heads)} master={self.master} {state}>"

    def __enter__(self) -> "CameraGroup":
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- frames in ------------------------------------------------------------------------------
    def _collect(self, name: str, cam: Camera) -> None:
        while not self._closed.is_set():
            self._heard_by_counter(name, cam)
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
                now = time.monotonic()
                self._last_frame[name] = now
                self._matcher.add(name, frame, now)
                self._cond.notify_all()

    def _heard_by_counter(self, name: str, cam: Camera) -> None:
        """A head whose ``triggers`` counter grew (heartbeat STATUS) hears the line even while its
        frames are still on their way (a loaded host, a slow link)."""
        status = cam.last_status
        count = status.counters.get("triggers", 0) if status is not None else 0
        if count > self._triggers.get(name, 0):
            with self._cond:
                self._triggers[name] = count
                self._last_frame[name] = time.monotonic()

    # -- sets out -------------------------------------------------------------------------------
    def get_set(self, timeout: float | None = None) -> MatchedSet:
        """The next set, in trigger-id order: complete, or with ``missing`` naming the cameras
        whose frame for that trigger did not come within the deadline. CameraTimeoutError if
        none within ``timeout`` (the first call waits ``settle`` longer); the error of a camera whose
        link died. SilentHeadsError, once per silence, naming the cameras that delivered nothing for
        ``SILENT_PERIODS`` frame periods (at least the deadline) while another streamed: their trigger
        input hears no pulses (later calls give the sets, with those cameras in ``missing``)."""
        timeout = self.timeout if timeout is None else timeout_arg(timeout)
        wait = timeout if self._first_given else timeout + self._settle
        deadline = time.monotonic() + wait
        with self._cond:
            while True:
                if self._closed.is_set():
                    raise TransportError(f"CameraGroup {', '.join(self.cameras) or ', '.join(self.urls)} is closed")
                if self._matcher is None:
                    raise StereoCamError("CameraGroup is not open (use it as a context manager or call open())")
                for s in self._matcher.pop_ready(time.monotonic()):
                    self._ready.append(s)
                    if len(self._ready) > READY_KEEP:
                        self._ready.popleft()
                        self.discarded += 1
                self._check_silence(time.monotonic())
                if self._ready:
                    self._first_given = True
                    return self._ready.popleft()
                if self._errors:
                    name, exc = next(iter(self._errors.items()))
                    raise type(exc)(f"camera {name}: {exc}") from exc
                left = deadline - time.monotonic()
                if left <= 0:
                    raise CameraTimeoutError(f"no matched set from {', '.join(self.cameras)} within {wait:.3g} s"
                                             f"{'' if self._last_frame else ': no camera has seen a trigger pulse'}")
                self._cond.wait(min(left, self._deadline / 4))

    def silent_heads(self, now: float | None = None) -> tuple[str, ...]:
        """The cameras that delivered no frame for ``SILENT_PERIODS`` frame periods (at least the
        deadline) while another camera did: their trigger input hears no pulses."""
        now = time.monotonic() if now is None else now
        with self._cond:
            quiet = self._quiet
            if not self._started or not any(now - t <= quiet for t in self._last_frame.values()):
                return ()  # nobody streams: the line itself is quiet (get_set's timeout says so)
            return tuple(n for n in self.cameras if now - self._last_frame.get(n, self._started) > quiet)

    @property
    def _quiet(self) -> float:
        """How long a head may show nothing before it is silent: SILENT_PERIODS frame periods, at least
        the deadline and two heartbeats (its STATUS counters show pulses its frames have not yet)."""
        heartbeat = float(self._open_kwargs.get("heartbeat_interval", HEARTBEAT_INTERVAL))
        return max(SILENT_PERIODS * self._period, self._deadline, 2 * heartbeat)

    def _check_silence(self, now: float) -> None:
        silent = self.silent_heads(now)
        new = [n for n in silent if n not in self._reported]
        self._reported = set(silent)  # a head that comes back and falls silent again is named again
        if new:
            quiet = self._quiet
            heard = [n for n in self.cameras if n not in silent]
            heads = ", ".join(f"{n} ({self._url_of[n]})" for n in new)
            raise SilentHeadsError(f"{heads}: no frame for {quiet:.2g} s while {', '.join(heard)} streamed; "
                                   f"{'its' if len(new) == 1 else 'their'} trigger input sees no pulses (is the "
                                   "trigger cable plugged? simulated heads share a line with sim://?...&line=NAME)",
                                   tuple(new))

    def __iter__(self) -> Iterator[MatchedSet]:
        """Sets as they come, until none arrives within ``timeout`` or the group is closed."""
        while True:
            try:
                yield self.get_set()
            except CameraTimeoutError:
                return
            except TransportError:
                if not self._closed.is_set():
                    raise
                return

    @property
    def stats(self) -> SetStats:
        """Complete and incomplete sets, missing frames by camera, late frames."""
        return self._matcher.stats if self._matcher is not None else SetStats()

    def clock_errors(self) -> dict[str, MapError]:
        """Each camera's current clock-map error estimate."""
        return {name: cam.clock.error() for name, cam in self.cameras.items()}
