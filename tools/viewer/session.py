"""The viewer's side of the camera: a newest-frame slot listening to the camera's frames, JPEGs made
on demand (never queued), the point under the cursor, rates and counters, and a recording that
listens to every frame itself (the page shows the newest; the file misses none)."""
from __future__ import annotations

import collections
import itertools
import re
import threading
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

import stereocam
from stereocam.dispatch import DropPolicy, FrameQueue
from stereocam.presets import read_preset
from stereocam.recording import Recorder, RecordingListener, describe
from stereocam.protocol.params import Output, TriggerMode, defaults
from stereocam.tools.camera.info import value_name
from stereocam.tools.camera.pictures import colorize, depth_ticks, disparity_range

from . import settings
from .feed import Feed

PLANES = ("left", "right", "disparity")
JPEG_QUALITY = 85
RECONNECT_S = 2.0  # one reconnection attempt of the grab thread (it tries again until the camera is back)
WAITING_S = 1.5  # streaming without a frame this long (and two frame periods): the page says what it waits for
HISTOGRAM_BINS = 48
PRESET_NAME = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")
PRESET_SUFFIX = ".preset.json"


def turbo_stops(n: int = 16) -> list[str]:
    """The colour map the disparity image uses, as CSS colours from near (max disparity) to far."""
    lut = cv2.applyColorMap(np.linspace(255, 0, n).astype(np.uint8).reshape(-1, 1), cv2.COLORMAP_TURBO)
    return [f"rgb({r},{g},{b})" for b, g, r in lut[:, 0, :]]


class ViewerSession(Feed):
    """Owns the grab thread; every method is safe to call from any HTTP handler thread."""

    def __init__(self, cam: stereocam.Camera, record_dir: Path | None = None):
        self.cam = cam
        self.record_dir = Path.cwd() if record_dir is None else Path(record_dir)
        self._recording: RecordingListener | None = None
        self._slot = FrameQueue("viewer", policy=DropPolicy.KEEP_NEWEST)
        cam.add_listener(self._slot)
        cam.remove_listener(cam.frames)  # nobody calls get_frame here: no queue filling up and counting drops
        self._cond = threading.Condition()
        self._frame: stereocam.Frame | None = None
        self._jpegs: dict[tuple[int, str], bytes] = {}
        self._arrivals: collections.deque[float] = collections.deque(maxlen=60)
        self._unseen = 0  # frames taken from the slot but replaced before the page looked
        self.span_m: tuple[float, float] | None = None  # the near/far range the page asked for (metres)
        self._pulses: tuple[int, float] | None = None  # device trigger count and when it last changed
        self._meta: tuple[int, dict[str, Any]] | None = None  # (sequence, frame_meta) of the newest frame
        self._start("stereocam-viewer-grab")

    # -- frames ---------------------------------------------------------------------------------
    @property
    def skipped(self) -> int:
        """Frames replaced by a newer one before anybody looked: never a backlog."""
        return self._slot.dropped + self._unseen

    def _fetch(self) -> stereocam.Frame:
        frame = self._slot.get(0.1)
        if frame is None:
            self.cam.connection.check_alive()  # a dead link shows on the page
            raise stereocam.CameraTimeoutError("no frame in 0.1 s")
        return frame

    def _recover(self, exc: stereocam.StereoCamError) -> None:
        """A lost link (the camera restarted, a cable): find the same unit again, with the settings
        this viewer made and its stream; until then the page shows the last frame as stale."""
        if isinstance(exc, stereocam.DisconnectedError):
            try:
                self.cam.reconnect(timeout=RECONNECT_S)
            except stereocam.StereoCamError as again:
                self.error = f"camera lost, reconnecting: {again}"

    @property
    def stale(self) -> bool:
        """Whether the newest frame is no longer live (the camera failed since it came)."""
        return self.error is not None

    def _take(self, frame: stereocam.Frame) -> None:
        with self._cond:
            if self._frame is not None and (self._frame.sequence, "left") not in self._jpegs:
                self._unseen += 1
            self._frame = frame
            self._jpegs = {k: v for k, v in self._jpegs.items() if k[0] == frame.sequence}
            self._arrivals.append(time.monotonic())
            self._cond.notify_all()

    # -- recording ------------------------------------------------------------------------------
    def start_recording(self) -> dict[str, Any]:
        """Record every frame from now on to a new MCAP file in ``record_dir``; returns its state."""
        with self._cond:
            if self._recording is not None:
                raise ValueError(f"already recording to {self._recording.recorder.path}")
        serial = re.sub(r"[^A-Za-z0-9_.-]", "_", self.cam.info().serial)[:64]  # the device names it: no paths
        stem = f"view_{serial}_{time.strftime('%Y%m%d-%H%M%S')}"
        path = self.record_dir / f"{stem}.mcap"
        for n in itertools.count(2):  # two recordings in one second: never over the first
            if not path.exists():
                break
            path = self.record_dir / f"{stem}-{n}.mcap"
        listener = RecordingListener(self.cam, Recorder(path, describe(self.cam)))
        with self._cond:
            self._recording = listener
        self.cam.add_listener(listener)
        return self.recording() or {}

    def stop_recording(self) -> dict[str, Any]:
        """Finish the file (summary and index); returns its final state."""
        with self._cond:
            listener, self._recording = self._recording, None
        if listener is None:
            raise ValueError("not recording")
        self.cam.remove_listener(listener)
        stats = listener.recorder.close()
        return {"path": str(listener.recorder.path), "frames": listener.frames,
                "recorder_dropped": stats.recorder_dropped, "megabytes": round(stats.file_bytes / 1e6, 2),
                "done": True}

    @property
    def recording_error(self) -> str | None:
        """Why the recording stopped taking frames (the disk failed); the view goes on."""
        listener = self._recording
        return f"recording stopped: {listener.error}" if listener is not None and listener.error else None

    def recording(self) -> dict[str, Any] | None:
        with self._cond:
            listener = self._recording
        if listener is None:
            return None
        recorder = listener.recorder
        return {"path": str(recorder.path), "frames": listener.frames,
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

    def _image(self, frame: stereocam.Frame, plane: str) -> np.ndarray | None:
        if plane == "disparity":
            return colorize(frame, self.span(frame)) if frame.disparity is not None else None
        return getattr(frame, plane)

    # -- the near/far range of the colour map, the histogram and the 3-D view --------------------
    def span(self, frame: stereocam.Frame) -> tuple[float, float]:
        """The disparities (px) at the colour map's ends: the page's near/far range, else the
        range the matcher searched."""
        if self.span_m is None:
            return disparity_range(frame)
        fb = frame.geometry.focal_px * frame.geometry.baseline_m
        near, far = self.span_m
        return fb / far, fb / near

    def set_span(self, near_m: float | None, far_m: float | None) -> dict[str, Any]:
        """Colour (and histogram) from ``near_m`` to ``far_m`` metres; both None: the searched range."""
        if near_m is None and far_m is None:
            self.span_m = None
        elif (isinstance(near_m, (int, float)) and isinstance(far_m, (int, float)) and not isinstance(near_m, bool)
              and not isinstance(far_m, bool) and 0 < near_m < far_m <= 1e4):
            self.span_m = (float(near_m), float(far_m))
        else:
            raise ValueError(f"near_m and far_m must be metres with 0 < near < far <= 10000, got {near_m!r}, {far_m!r}")
        with self._cond:
            self._jpegs.clear()
            self._meta = None
        return self.span_doc()

    def span_doc(self) -> dict[str, float | None]:
        near, far = self.span_m or (None, None)
        return {"near_m": near, "far_m": far}

    def histogram(self, frame: stereocam.Frame) -> dict[str, Any]:
        """Valid pixels per depth bin across the colour map's range (near to far), with the pixels
        nearer and farther than it and the invalid ones."""
        lo, hi = self.span(frame)
        fb = frame.geometry.focal_px * frame.geometry.baseline_m
        d = frame.disparity_px()
        valid = d[d > 0]
        z = fb / valid
        near_m = fb / hi
        if self.span_m is not None:
            far_m = fb / lo
        else:  # the searched range may reach infinity (min_disparity 0): the farthest 1 % is left out
            far_m = fb / lo if lo > 0 else max(float(np.percentile(z, 99)) if z.size else 2 * near_m, 1.01 * near_m)
        counts, edges = np.histogram(z, bins=HISTOGRAM_BINS, range=(near_m, far_m))
        return {"near_m": round(near_m, 3), "far_m": round(far_m, 3), "counts": counts.tolist(),
                "nearer": int((z < near_m).sum()), "farther": int((z > far_m).sum()),
                "invalid": int(d.size - valid.size)}

    def fps(self) -> float:
        with self._cond:
            t = list(self._arrivals)
        recent = [x for x in t if x > time.monotonic() - 2.0]
        return (len(recent) - 1) / (recent[-1] - recent[0]) if len(recent) > 2 and recent[-1] > recent[0] else 0.0

    # -- what the page shows --------------------------------------------------------------------
    def frame_meta(self, frame: stereocam.Frame) -> dict[str, Any]:
        """The frame's size, planes, colour bar (ticks in metres) and depth histogram."""
        with self._cond:
            if self._meta is not None and self._meta[0] == frame.sequence:
                return {**self._meta[1], "stale": self.stale}
        meta: dict[str, Any] = {"sequence": frame.sequence, "width": frame.width, "height": frame.height,
                                "rectified": frame.rectified, "status": frame.status.value,
                                "planes": [p for p in PLANES if getattr(frame, p) is not None]}
        if frame.disparity is not None:
            lo, hi = self.span(frame)
            meta["colorbar"] = {"near_to_far": turbo_stops(),
                                "ticks": [{"at": (hi - d) / (hi - lo), "metres": z}
                                          for d, z in depth_ticks(frame, span=(lo, hi))]}
            meta["histogram"] = self.histogram(frame)
        with self._cond:
            self._meta = (frame.sequence, meta)
        return {**meta, "stale": self.stale}

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

    def frame_age(self) -> float | None:
        """Seconds since the newest frame came (None before the first)."""
        with self._cond:
            return time.monotonic() - self._arrivals[-1] if self._arrivals else None

    def waiting(self, config: dict[str, int], counters: dict[str, int]) -> str | None:
        """What a streaming camera without frames waits for: an external pulse (and whether the
        device has seen one lately), a software trigger; None while frames come."""
        pulses = counters.get("triggers")
        now = time.monotonic()
        if pulses is not None and (self._pulses is None or self._pulses[0] != pulses):
            self._pulses = (pulses, now)
        age = self.frame_age()
        quiet = max(WAITING_S, 2.0 / max(config.get("fps", 1), 1))
        if not self.cam.streaming or (age is not None and age < quiet):
            return None
        mode = config.get("trigger_mode")
        if mode == TriggerMode.EXTERNAL:
            if self._pulses is None or now - self._pulses[1] >= quiet:
                return "waiting for external trigger: no pulse seen on the trigger input"
            return "waiting for external trigger"
        if mode == TriggerMode.SOFTWARE:
            return "waiting for a software trigger (press Trigger)"
        return None

    def expected_planes(self, config: dict[str, int]) -> list[str]:
        """The planes the configuration asks for (``outputs``; disparity only when rectified)."""
        outputs = Output(config.get("outputs", 0))
        return [p for p in PLANES if Output[p.upper()] in outputs and (p != "disparity" or config.get("rectify", 1))]

    def state(self) -> dict[str, Any]:
        cam = self.cam
        info = cam.info()
        config = cam.config()
        status = cam.last_status
        device = dict(status.counters) if status else {}
        age = self.frame_age()
        return {
            "url": cam.url, "model": info.model, "serial": info.serial, "firmware": info.firmware_version,
            "streaming": cam.streaming, "fps": round(self.fps(), 1), "viewer_skipped": self.skipped,
            "stale": self.stale, "frame_age_s": None if age is None else round(age, 2),
            "waiting": self.waiting(config, device), "expected_planes": self.expected_planes(config),
            "error": self.error or self.recording_error, "recording": self.recording(), "host": cam.stats,
            "device": device, "config": config, "config_names": {k: value_name(k, v) for k, v in config.items()},
            "groups": [*settings.GROUPS, settings.OTHER],
            "options": [settings.describe(p, config.get(p.name)) for p in cam.options() if p.name in config],
            "presets": self.presets(), "span": self.span_doc(),
        }

    # -- configuration: defaults and presets ---------------------------------------------------
    def reset(self) -> dict[str, int]:
        """Every setting to the table's default (stopping the stream for those only a stopped camera
        takes, and starting it again); returns the new configuration."""
        config = self.cam.config()
        changed = {k: v for k, v in defaults().items() if k in config and config[k] != v}
        return self._apply(changed)

    def _apply(self, values: dict[str, int]) -> dict[str, int]:
        """``values`` applied, around a stop and start if one of them is not live."""
        restart = self.cam.streaming and any(not p.live for p in self.cam.options() if p.name in values)
        if restart:
            self.cam.stop()
        try:
            return self.cam.configure(**values)
        finally:
            if restart:
                self.cam.start()

    def _preset_path(self, name: object) -> Path:
        if not isinstance(name, str) or not PRESET_NAME.match(name) or name.startswith("."):
            raise ValueError(f"a preset name is 1..64 letters, digits, '_', '-' or '.', got {name!r}")
        return self.record_dir / f"{name}{PRESET_SUFFIX}"

    def presets(self) -> list[str]:
        """The presets saved in ``record_dir``, by name."""
        try:
            return sorted(p.name[:-len(PRESET_SUFFIX)] for p in self.record_dir.glob(f"*{PRESET_SUFFIX}"))
        except OSError:
            return []

    def save_preset(self, name: object) -> dict[str, Any]:
        """The whole configuration to ``record_dir``/NAME.preset.json (the SDK's preset file)."""
        path = self._preset_path(name)
        return {"preset": name, "path": str(path), "config": self.cam.save_preset(path)}

    def load_preset(self, name: object) -> dict[str, Any]:
        """Apply a saved preset (all or nothing); returns the new configuration."""
        path = self._preset_path(name)
        if not path.exists():
            raise ValueError(f"no preset {name!r} in {self.record_dir}")
        return {"preset": name, "config": self._apply(read_preset(path))}

    def close(self) -> None:
        super().close()
        self.cam.remove_listener(self._slot)
        if self._recording is not None:
            self.stop_recording()
