"""The viewer's side of a camera group (``stereocam view URL URL ...``): the newest matched set,
its images as JPEGs made on demand, the spread of its capture times, the sets a head missed (which
head, which trigger) and each head's clock-map error estimate."""
from __future__ import annotations

import threading
from typing import Any

import cv2

import stereocam
from stereocam.frame_sets import MatchedSet
from stereocam.tools.camera.pictures import colorize

from .feed import Feed
from .session import JPEG_QUALITY

PLANES = ("left", "disparity")
MISSED_KEEP = 20  # incomplete sets listed on the page (newest first)


class GroupViewerSession(Feed):
    """Owns the thread that takes matched sets from an open ``CameraGroup``."""

    def __init__(self, group: stereocam.CameraGroup):
        self.group = group
        self._models = {name: cam.info().model for name, cam in group.cameras.items()}  # read once
        self._cond = threading.Condition()
        self._set: MatchedSet | None = None
        self._jpegs: dict[tuple[int, str, str], bytes] = {}
        self.missed: list[dict[str, Any]] = []  # newest first
        self._start("stereocam-viewer-group")

    def _fetch(self) -> MatchedSet:
        return self.group.get_set(timeout=0.2)

    def _take(self, s: MatchedSet) -> None:
        with self._cond:
            if not s.complete:
                self.missed.insert(0, {"trigger_id": s.trigger_id, "missing": list(s.missing)})
                del self.missed[MISSED_KEEP:]
            if s.frames:
                self._set = s
                self._jpegs = {k: v for k, v in self._jpegs.items() if k[0] == s.trigger_id}
            self._cond.notify_all()

    def newest(self, after: int = -1, wait: float = 1.0) -> MatchedSet | None:
        """The newest set with frames, waiting up to ``wait`` s for one after trigger ``after``."""
        with self._cond:
            self._cond.wait_for(lambda: self._set is not None and self._set.trigger_id > after, wait)
            return self._set

    def jpeg(self, camera: str, plane: str) -> tuple[int, bytes] | None:
        """(trigger id, JPEG) of ``camera``'s ``plane`` in the newest set; None if it has none."""
        s = self.newest(wait=0)
        frame = s.frames.get(camera) if s is not None else None
        if frame is None or plane not in PLANES:
            return None
        key = (s.trigger_id, camera, plane)
        with self._cond:
            cached = self._jpegs.get(key)
        if cached is None:
            img = colorize(frame) if plane == "disparity" and frame.disparity is not None else getattr(frame, plane)
            if img is None:
                return None
            cached = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])[1].tobytes()
            with self._cond:
                self._jpegs[key] = cached
        return s.trigger_id, cached

    def set_meta(self, s: MatchedSet) -> dict[str, Any]:
        t0 = min(s.host_times.values())
        return {"trigger_id": s.trigger_id, "complete": s.complete, "missing": list(s.missing),
                "skew_us": round(s.skew * 1e6, 1),
                "frames": {name: {"sequence": f.sequence, "offset_us": round((f.host_time - t0) * 1e6, 1),
                                  "planes": [p for p in PLANES if getattr(f, p) is not None]}
                           for name, f in s.frames.items()}}

    def state(self) -> dict[str, Any]:
        st = self.group.stats
        errors = self.group.clock_errors()
        with self._cond:
            missed = list(self.missed)
        return {
            "cameras": [{"name": name, "url": cam.url, "model": self._models[name],
                         "clock_sigma_us": round(errors[name].sigma * 1e6, 1)}
                        for name, cam in self.group.cameras.items()],
            "sets": {"complete": st.complete, "incomplete": st.incomplete}, "missed": missed,
            "discarded": self.group.discarded, "error": self.error,
        }
