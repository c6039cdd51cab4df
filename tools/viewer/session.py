"""The viewer's side of the camera: a grab thread that keeps only the newest frame, JPEGs made on
demand (never queued), the point under the cursor, rates and counters, and a recording that gets
every frame (the page shows the newest; the file misses none)."""
from __future__ import annotations

import collections
import itertools
import re
import threading
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import cv2
import numpy as np

import stereocam
from stereocam.recording import Recorder, RecordingError, describe
from stereocam.recording.session import counters_of
from stereocam.tools.camera.info import value_name
from stereocam.tools.camera.pictures import colorize, depth_ticks, disparity_range

from .feed import Feed

PLANES = ("left", "right", "disparity")
JPEG_QUALITY = 85


def turbo_stops(n: int = 16) -> list[str]:
    """The colour map the disparity image uses, as CSS colours from near (max disparity) to far."""
    lut = cv2.applyColorMap(np.linspace(255, 0, n).astype(np.uint8).reshape(-1, 1), cv2.COLORMAP_TURBO)
    return [f"rgb({r},{g},{b})" for b, g, r in lut[:, 0, :]]


class ViewerSession(Feed):
    """Owns the grab thread; every method is safe to call from any HTTP handler thread."""

    def __init__(self, cam: stereocam.Camera, record_dir: Path | None = None):
        self.cam = cam
        self.record_dir = Path.cwd() if record_dir is None else Path(record_dir)
        self._recorder: Recorder | None = None
        self._recorded = 0
        self._cond = threading.Condition()
        self._frame: stereocam.Frame | None = None
        self._jpegs: dict[tuple[int, str], bytes] = {}
        self._arrivals: collections.deque[float] = collections.deque(maxlen=60)
        self.skipped = 0  # frames replaced by a newer one before anybody looked: never a backlog
        self.recording_error: str | None = None  # why the last recording ended early
        self._start("stereocam-viewer-grab")

    # -- frames ---------------------------------------------------------------------------------
    def _fetch(self) -> stereocam.Frame:
        frame = self.cam.get_frame(timeout=0.1)
        self._record(frame)
        while (newer := self.cam.try_get_frame()) is not None:  # only the newest is shown
            self._record(newer)
            frame, self.skipped = newer, self.skipped + 1
        return frame

    def _take(self, frame: stereocam.Frame) -> None:
        with self._cond:
            if self._frame is not None and (self._frame.sequence, "left") not in self._jpegs:
                self.skipped += 1
            self._frame = frame
            self._jpegs = {k: v for k, v in self._jpegs.items() if k[0] == frame.sequence}
            self._arrivals.append(time.monotonic())
            self._cond.notify_all()

    # -- recording ------------------------------------------------------------------------------
    def _record(self, frame: stereocam.Frame) -> None:
        with self._cond:
            recorder = self._recorder
            if recorder is None:
                return
            try:
                recorder.put(frame, counters_of(self.cam))
                self._recorded += 1
            except RecordingError as exc:  # the disk failed: the recording ends, said so; the view goes on
                self._recorder, self.recording_error = None, f"recording stopped: {exc}"

    def start_recording(self) -> dict[str, Any]:
        """Record every frame from now on to a new MCAP file in ``record_dir``; returns its state."""
        with self._cond:
            if self._recorder is not None:
                raise ValueError(f"already recording to {self._recorder.path}")
        serial = re.sub(r"[^A-Za-z0-9_.-]", "_", self.cam.info().serial)[:64]  # the device names it: no paths
        stem = f"view_{serial}_{time.strftime('%Y%m%d-%H%M%S')}"
        path = self.record_dir / f"{stem}.mcap"
        for n in itertools.count(2):  # two recordings in one second: never over the first
            if not path.exists():
                break
            path = self.record_dir / f"{stem}-{n}.mcap"
        recorder = Recorder(path, describe(self.cam))
        with self._cond:
            self._recorder, self._recorded, self.recording_error = recorder, 0, None
        return self.recording() or {}

    def stop_recording(self) -> dict[str, Any]:
        """Finish the file (summary and index); returns its final state."""
        with self._cond:
            recorder, self._recorder = self._recorder, None
        if recorder is None:
            raise ValueError("not recording")
        stats = recorder.close()
        return {"path": str(recorder.path), "frames": self._recorded, "recorder_dropped": stats.recorder_dropped,
                "megabytes": round(stats.file_bytes / 1e6, 2), "done": True}

    def recording(self) -> dict[str, Any] | None:
        with self._cond:
            recorder = self._recorder
        if recorder is None:
            return None
        return {"path": str(recorder.path), "frames": self._recorded,
                "recorder_dropped": recorder.stats.recorder_dropped,
                "megabytes": round(recorder.stats.file_bytes / 1e6, 2), "done": False}

    def newest(self, after: int = -1, wait: float = 1.0) -> stereocam.Frame | None:
        """The newest frame, waiting up to ``wait`` seconds for one newer than ``after``."""
        deadline = time.monotonic() + wait
        with self._cond:
            while (self._frame is None or self._frame.sequence <= after) and time.monotonic() < deadline:
                self._cond.wait(max(deadline - time.monotonic(), 0.0))
            return self._frame

    def jpeg(self, plane: str) -> tuple[int, bytes] | None:
        """(sequence, JPEG) of the newest frame's ``plane``; None if there is no such image."""
        frame = self.newest(wait=0)
        if frame is None or plane not in PLANES:
            return None
        key = (frame.sequence, plane)
        with self._cond:
            cached = self._jpegs.get(key)
        if cached is None:
            img = self._image(frame, plane)
            if img is None:
                return None
            cached = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])[1].tobytes()
            with self._cond:
                if self._frame is not None and self._frame.sequence == frame.sequence:
                    self._jpegs[key] = cached
        return frame.sequence, cached

    @staticmethod
    def _image(frame: stereocam.Frame, plane: str) -> np.ndarray | None:
        if plane == "disparity":
            return colorize(frame) if frame.disparity is not None else None
        return getattr(frame, plane)

    def fps(self) -> float:
        with self._cond:
            t = list(self._arrivals)
        recent = [x for x in t if x > time.monotonic() - 2.0]
        return (len(recent) - 1) / (recent[-1] - recent[0]) if len(recent) > 2 and recent[-1] > recent[0] else 0.0

    # -- what the page shows --------------------------------------------------------------------
    def frame_meta(self, frame: stereocam.Frame) -> dict[str, Any]:
        meta: dict[str, Any] = {"sequence": frame.sequence, "width": frame.width, "height": frame.height,
                                "rectified": frame.rectified, "status": frame.status.value,
                                "planes": [p for p in PLANES if getattr(frame, p) is not None]}
        if frame.disparity is not None:
            lo, hi = disparity_range(frame)
            meta["colorbar"] = {"near_to_far": turbo_stops(),
                                "ticks": [{"at": (hi - d) / (hi - lo), "metres": z} for d, z in depth_ticks(frame)]}
        return meta

    def point(self, x: int, y: int) -> dict[str, Any]:
        """Disparity, depth and the 3-D point (metres, left camera frame) at pixel (x, y) of the newest frame."""
        frame = self.newest(wait=0)
        if frame is None or frame.disparity is None or not (0 <= x < frame.width and 0 <= y < frame.height):
            return {"x": x, "y": y, "valid": False}
        d = float(frame.disparity_px()[y, x])
        g = frame.geometry
        if not d > 0:
            return {"x": x, "y": y, "sequence": frame.sequence, "valid": False}
        z = g.focal_px * g.baseline_m / d
        return {"x": x, "y": y, "sequence": frame.sequence, "valid": True, "disparity_px": d, "depth_m": z,
                "point_m": [(x - g.cx) * z / g.focal_px, (y - g.cy) * z / g.focal_px, z]}

    def state(self) -> dict[str, Any]:
        cam = self.cam
        info = cam.info()
        config = cam.config()
        status = cam.last_status
        return {
            "url": cam.url, "model": info.model, "serial": info.serial, "firmware": info.firmware_version,
            "streaming": cam.streaming, "fps": round(self.fps(), 1), "viewer_skipped": self.skipped,
            "error": self.error or self.recording_error, "recording": self.recording(), "host": cam.stats, "device": dict(status.counters) if status else {},
            "config": config, "config_names": {k: value_name(k, v) for k, v in config.items()},
            "options": [{**asdict(p), "value": config.get(p.name)} for p in cam.options() if p.name in config],
        }

    def close(self) -> None:
        super().close()
        if self._recorder is not None:
            self.stop_recording()
