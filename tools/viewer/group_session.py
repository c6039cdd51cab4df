"""The viewer's side of a camera group (``stereocam view URL URL ...``): the newest matched set,
each head's last frame (kept, with its age, when the head missed the newest set), its images as
JPEGs made on demand, the colour bar, the spread of capture times, the sets a head missed and each
head's clock-map error estimate; start, stop, one set on demand and settings for every head."""
from __future__ import annotations

import threading
import time
from typing import Any

import cv2

import stereocam
from stereocam.frame_sets import MatchedSet
from stereocam.tools.camera.info import value_name
from stereocam.tools.camera.pictures import colorize, depth_ticks, disparity_range

from . import settings
from .feed import Feed
from .session import JPEG_QUALITY, turbo_stops

PLANES = ("left", "disparity")
MISSED_KEEP = 20  # incomplete sets listed on the page (newest first)
GROUP_OWNS = ("trigger_mode", "trigger_output")  # the group sets these itself (one line, one master)
ONE_SET_S = 10.0  # how long Trigger waits for the set it asked for


class GroupViewerSession(Feed):
    """Owns the thread that takes matched sets from an open ``CameraGroup``."""

    def __init__(self, group: stereocam.CameraGroup):
        self.group = group
        self._models = {name: cam.info().model for name, cam in group.cameras.items()}  # read once
        self._cond = threading.Condition()
        self._set: MatchedSet | None = None
        self._last: dict[str, tuple[int, stereocam.Frame, float]] = {}  # head -> (trigger, frame, when it came)
        self._jpegs: dict[tuple[int, str, str], bytes] = {}
        self._action = threading.Lock()  # one start/stop/trigger at a time
        self.missed: list[dict[str, Any]] = []  # newest first
        self._start("stereocam-viewer-group")

    def _fetch(self) -> MatchedSet:
        return self.group.get_set(timeout=0.2)

    def _take(self, s: MatchedSet) -> None:
        now = time.monotonic()
        with self._cond:
            if not s.complete:
                self.missed.insert(0, {"trigger_id": s.trigger_id, "missing": list(s.missing)})
                del self.missed[MISSED_KEEP:]
            if s.frames:
                self._set = s
                for name, frame in s.frames.items():
                    self._last[name] = (s.trigger_id, frame, now)
                kept = {(t, name) for name, (t, _, _) in self._last.items()}
                self._jpegs = {k: v for k, v in self._jpegs.items() if (k[0], k[1]) in kept}
            self._cond.notify_all()

    def newest(self, after: int = -1, wait: float = 1.0) -> MatchedSet | None:
        """The newest set with frames, waiting up to ``wait`` s for one after trigger ``after``."""
        with self._cond:
            self._cond.wait_for(lambda: self._set is not None and self._set.trigger_id > after, wait)
            return self._set

    def jpeg(self, camera: str, plane: str) -> tuple[int, bytes] | None:
        """(trigger id, JPEG) of ``camera``'s ``plane`` in its last frame (the newest set's, or the
        one before it missed); None if it has none."""
        with self._cond:
            last = self._last.get(camera)
        if last is None or plane not in PLANES:
            return None
        trigger_id, frame, _ = last
        key = (trigger_id, camera, plane)
        with self._cond:
            cached = self._jpegs.get(key)
        if cached is None:
            img = colorize(frame) if plane == "disparity" and frame.disparity is not None else getattr(frame, plane)
            if img is None:
                return None
            cached = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])[1].tobytes()
            with self._cond:
                self._jpegs[key] = cached
        return trigger_id, cached

    def set_meta(self, s: MatchedSet) -> dict[str, Any]:
        t0 = min(s.host_times.values())
        now = time.monotonic()
        with self._cond:
            last = dict(self._last)
        meta: dict[str, Any] = {
            "trigger_id": s.trigger_id, "complete": s.complete, "missing": list(s.missing),
            "skew_us": round(s.skew * 1e6, 1),
            "frames": {name: {"sequence": f.sequence, "offset_us": round((f.host_time - t0) * 1e6, 1),
                              "planes": [p for p in PLANES if getattr(f, p) is not None]}
                       for name, f in s.frames.items()},
            "heads": {name: {"trigger_id": t, "sequence": f.sequence, "age_s": round(now - came, 2),
                             "missed": t != s.trigger_id,
                             "planes": [p for p in PLANES if getattr(f, p) is not None]}
                      for name, (t, f, came) in last.items()}}
        frame = next((f for f in s.frames.values() if f.disparity is not None), None)
        if frame is not None:
            lo, hi = disparity_range(frame)
            meta["colorbar"] = {"near_to_far": turbo_stops(),
                                "ticks": [{"at": (hi - d) / (hi - lo), "metres": z} for d, z in depth_ticks(frame)]}
        return meta

    # -- actions on every head ------------------------------------------------------------------
    def _order(self, starting: bool) -> list[stereocam.Camera]:
        """The heads, the master last when starting (its first pulse finds every head streaming)
        and first when stopping (no pulse reaches a head that stopped)."""
        cams = list(self.group.cameras.values())
        if self.group.master is not None:
            cams.append(cams.pop(self.group.master))
        return cams if starting else cams[::-1]

    def start(self) -> None:
        with self._action:
            for cam in self._order(starting=True):
                cam.start()

    def stop(self) -> None:
        with self._action:
            for cam in self._order(starting=False):
                cam.stop()

    def one_set(self) -> dict[str, Any]:
        """Trigger: one matched set on demand from stopped heads (start, the master's first pulse,
        stop); ValueError while streaming (the master pulses at its frame rate already)."""
        if any(cam.streaming for cam in self.group.cameras.values()):
            raise ValueError("the group is streaming (its master triggers every head at fps): stop it first "
                             "to take one set with Trigger")
        before = self._set.trigger_id if self._set is not None else -1
        self.start()
        try:
            got = self.newest(before, ONE_SET_S)
        finally:
            self.stop()
        if got is None or got.trigger_id <= before:
            raise stereocam.CameraTimeoutError(f"no set within {ONE_SET_S:g} s")
        return {"trigger_id": got.trigger_id, "complete": got.complete}

    def configure(self, values: dict[str, int]) -> dict[str, int | None]:
        """The same settings on every head; a refusal names the head and puts back the heads
        already changed, so the group never ends up split."""
        owned = sorted(set(values) & set(GROUP_OWNS))
        if owned:
            raise ValueError(f"{', '.join(owned)}: the group sets these itself (one trigger line, one master)")
        done: list[tuple[stereocam.Camera, dict[str, int]]] = []
        for name, cam in self.group.cameras.items():
            before = cam.config()
            try:
                cam.configure(**values)
            except stereocam.DeviceError as exc:
                for changed, config in done:
                    changed.configure(**{k: config[k] for k in values})
                raise stereocam.DeviceError(int(exc.code), f"camera {name}: {exc.device_message}", exc.param,
                                            exc.request_type) from exc
            done.append((cam, before))
        return self.shared_config()

    def shared_config(self) -> dict[str, int | None]:
        """Each setting's value if every head has it, else None (the heads differ)."""
        configs = [cam.config() for cam in self.group.cameras.values()]
        return {k: v if all(c.get(k) == v for c in configs) else None for k, v in configs[0].items()}

    def state(self) -> dict[str, Any]:
        st = self.group.stats
        errors = self.group.clock_errors()
        with self._cond:
            missed = list(self.missed)
        config = self.shared_config()
        return {
            "cameras": [{"name": name, "url": cam.url, "model": self._models[name],
                         "clock_sigma_us": round(errors[name].sigma * 1e6, 1), "streaming": cam.streaming}
                        for name, cam in self.group.cameras.items()],
            "sets": {"complete": st.complete, "incomplete": st.incomplete}, "missed": missed,
            "discarded": self.group.discarded, "error": self.error,
            "config_names": {k: value_name(k, v) for k, v in config.items() if v is not None},
            "groups": [*settings.GROUPS, settings.OTHER],
            "options": [settings.describe(p, config.get(p.name)) for p in stereocam.Camera.options()
                        if p.name in config and p.name not in GROUP_OWNS],
        }
