"""A recording as the frame source of the simulated firmware: replay as a device.

``ReplaySource`` stands where the sensor rig stands: per capture it gives what the unit sent then
(rectified left and right, disparity, sequence number, trigger id, device time, geometry). The
firmware around it is the same one that serves every simulator (INFO, configuration, calibration
reads, streaming over every transport), so a host cannot tell a replay from the camera:

* identity: the recorded model, serial and firmware version; the recorded configuration at boot
  (in free run whatever triggered the recorded unit: the recording paces the replay);
  the recorded calibration in flash (same body, so the same calibration id in every frame);
* timing: ``realtime`` plays captures at their recorded device-time spacing, else as fast as the
  host reads (the link's back-pressure paces it); recorded times are not trusted: a step backwards
  or of more than ``MAX_PACE_GAP_S`` restarts the pacing at that capture (played at once), and
  closing the replay interrupts any wait; ``loop`` starts over at the end, else the stream
  ends; ``start`` is the first frame index (found through the file's index, nothing before read);
* disparity: with the recorded matching configuration the recorded plane is resent as it was;
  after the host changes any matching parameter the recorded images are matched again on board.
"""
from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterator

import numpy as np

from stereocam.protocol import messages as m
from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.errors import ConfigError
from stereocam.protocol.frame_messages import DISPARITY_SUBPIXEL, invalid_disparity
from stereocam.protocol.params import BY_NAME, Output, TriggerMode, defaults
from stereocam.stereo.engines import params_from_config
from stereocam.stereo.post import post_params_from_config

from .clock import REAL_CLOCK, Clock
from .pipeline.capture_engine import CaptureEngine, CaptureRequest

if TYPE_CHECKING:
    from stereocam.recording.reader import RecordedCapture

_log = logging.getLogger(__name__)

IDENTITY = ("model", "serial", "firmware_version")  # what a replayed unit needs of the recorded INFO
Matcher = Callable[[dict, np.ndarray, np.ndarray], np.ndarray]
MAX_PACE_GAP_S = 10.0  # longest recorded pause replayed as a pause; a longer (or backward) step re-anchors


@dataclass(frozen=True)
class ReplayedCapture:
    """One capture ready for the wire: its FRAME_BEGIN and its planes (None: not sent)."""

    begin: m.FrameBegin
    planes: dict[Output, np.ndarray]


class ReplayClock:
    """The device clock of a replay: it reads the recorded device time of the start frame when the
    replay opens and runs at the speed of ``timebase`` from there (what TIME_SYNC answers)."""

    drift = 0.0  # no crystal of its own: it counts at the time base's rate

    def __init__(self, start_us: int, timebase: Clock = REAL_CLOCK):
        self.timebase = timebase
        self.boot = timebase.monotonic()
        self.epoch_us = start_us

    def now_us(self) -> int:
        return self.at(self.timebase.monotonic())

    def at(self, host_monotonic: float) -> int:
        return int((host_monotonic - self.boot) * 1e6) + self.epoch_us

    def uptime_us(self) -> int:
        return int((self.timebase.monotonic() - self.boot) * 1e6)

    def host_period(self, device_seconds: float) -> float:
        return device_seconds


class ReplaySource:
    """Captures of a recording, in order from ``start``, for the firmware to send, paced on ``timebase``."""

    def __init__(self, path: str | Path, *, realtime: bool = True, loop: bool = False, start: int = 0,
                 timebase: Clock = REAL_CLOCK):
        from stereocam.recording.reader import Recording  # the recording extra, needed only here

        self.recording = Recording(path)
        self.timebase = timebase
        try:
            self._open(path, start)
        except BaseException:
            self.recording.close()
            raise
        self.path = str(path)
        self.realtime, self.loop, self.start = realtime, loop, start
        self.finished = False  # played once to the end (the stream sends nothing more until restarted)
        self._lock = threading.Lock()
        self._iter: Iterator[RecordedCapture] | None = None
        self._pending: RecordedCapture | None = None
        self._t0: tuple[float, int] | None = None  # (host monotonic, device µs) the pacing counts from
        self._last_us: int | None = None  # the recorded device time of the capture last paced
        self._closed = threading.Event()
        self.sent = 0

    def _open(self, path: str | Path, start: int) -> None:
        """The recorded unit (identity, configuration, calibration) and the clock at frame ``start``."""
        if not len(self.recording):
            raise ConfigError(f"{path} holds no captures to replay")
        if not 0 <= start < len(self.recording):
            raise ConfigError(f"start frame {start} outside a recording of {len(self.recording)} frames")
        d = self.recording.device
        missing = [k for k in IDENTITY if k not in d]
        if missing:
            from stereocam.recording.reader import DamagedRecordingError

            raise DamagedRecordingError(f"{path}: metadata stereocam.device has no {', '.join(missing)}: the "
                                        f"recorded unit cannot be replayed")
        self.model, self.serial, self.firmware_version = (d[k] for k in IDENTITY)
        self.config = self.recording.config
        stored = self.recording.calibration
        self.calibration: StereoCalibration | None = stored.calibration if stored else None
        self.clock = ReplayClock(self.recording.capture(start).info.device_time_us, self.timebase)

    def boot_config(self) -> dict[str, int]:
        """The recorded configuration a replayed unit boots with, less how the recorded unit was
        triggered: a replay is paced by its recording (free run, no trigger output); every frame
        still carries its recorded trigger id."""
        paced = {"trigger_mode": int(TriggerMode.FREE_RUN), "trigger_output": 0}
        return {k: paced.get(k, v) for k, v in self.config.items() if k in BY_NAME}

    # -- the engine's side: what to capture next, and when -------------------------------------
    def restart(self) -> None:
        """A new stream: play from ``start`` again (a capture taken for the old stream stays pending:
        the firmware finds it no longer current and does not send it)."""
        with self._lock:
            self._iter, self._t0, self._last_us = None, None, None
            self.finished = False

    def next_request(self, epoch: int, paced: bool = True) -> CaptureRequest | None:
        """The next capture as a request (recorded sequence and trigger id), once it is due (at once
        unless ``paced``: a trigger asked for it); None at the end of a recording played once."""
        with self._lock:
            if self._iter is None:
                self._iter = self.recording.captures(self.start)
            cap = self._next()
            if cap is None and self.loop:
                self._iter = self.recording.captures(self.start)
                self._t0, self._last_us = None, None
                cap = self._next()
            self._pending = cap
            self.finished = cap is None
        if cap is None:
            return None
        now, t_us = self.timebase.monotonic(), cap.info.device_time_us
        step_us = None if self._last_us is None else t_us - self._last_us
        if self._t0 is None or step_us is None or not 0 <= step_us <= MAX_PACE_GAP_S * 1e6:
            self._t0 = (now, t_us)
        self._last_us = t_us
        due = self._t0[0] + (t_us - self._t0[1]) / 1e6 if self.realtime and paced else now
        if due > now and self.timebase.wait(self._closed, due - now):
            return None
        return CaptureRequest(cap.info.sequence, cap.info.trigger_id, max(due, now), epoch)

    def _next(self) -> RecordedCapture | None:
        """The next readable capture: a damaged one is skipped (the host sees its sequence number
        missing, a drop it counts) and logged; None at the end."""
        from stereocam.recording.reader import DamagedRecordingError

        captures = self._iter
        assert captures is not None, "next_request opens the recording first"
        while True:
            try:
                return next(captures, None)
            except DamagedRecordingError as exc:
                if exc.frame is None:  # not one frame: reading cannot go on
                    raise
                _log.warning("replay: %s; skipped", exc)
                captures = self._iter = self.recording.captures(exc.frame + 1)

    # -- the firmware's side: the planes of that capture ---------------------------------------
    def capture(self, req: CaptureRequest, cfg: dict[str, int], match: Matcher) -> ReplayedCapture:
        """The capture ``req`` stands for, as ``cfg`` asks for it: the recorded disparity when the
        matching configuration is the recorded one, else the recorded images matched again."""
        cap = self._pending
        assert cap is not None
        i = cap.info
        ids = (i.sequence, i.trigger_id, i.device_time_us)
        if (req.sequence, req.trigger_id) != ids[:2]:  # taken on a trigger: its numbers, the replay's time
            ids = (req.sequence, req.trigger_id, self.clock.at(req.time))
        wanted = Output(cfg["outputs"]) & Output(i.planes | (Output.DISPARITY if i.rectified else 0))
        planes = {Output.LEFT: cap.left, Output.RIGHT: cap.right}
        recorded = {**defaults(), **self.config}
        same = (params_from_config(cfg) == params_from_config(recorded)  # the recorded matching
                and post_params_from_config(cfg) == post_params_from_config(recorded))  # and post-processing
        if Output.DISPARITY in wanted and same and cap.disparity is not None:
            planes[Output.DISPARITY] = cap.disparity
            fmt = (i.subpixel, i.min_disparity, i.num_disparities, i.invalid_disparity)
        elif Output.DISPARITY in wanted and cap.left is not None and cap.right is not None:
            planes[Output.DISPARITY] = match(cfg, cap.left, cap.right)
            fmt = (DISPARITY_SUBPIXEL, cfg["min_disparity"], cfg["num_disparities"],
                   invalid_disparity(cfg["min_disparity"]))
        else:
            fmt = (i.subpixel, i.min_disparity, i.num_disparities, i.invalid_disparity)
        sent = {p: a for p, a in planes.items() if p in wanted and a is not None}
        outputs = sum(int(p) for p in sent)
        begin = m.FrameBegin(*ids, i.exposure_us, i.gain, i.width, i.height,
                             outputs, m.FRAME_RECTIFIED if i.rectified else 0, m.DISPARITY_S16_Q4, *fmt,
                             i.calibration_id, i.focal_px, i.cx, i.cy, i.baseline_m)
        self.sent += 1
        return ReplayedCapture(begin, sent)

    def interrupt(self) -> None:
        """End any wait for a capture's due time (the replay is closing)."""
        self._closed.set()

    def close(self) -> None:
        self.interrupt()
        self.recording.close()


class ReplayEngine(CaptureEngine):
    """The capture engine of a replay: free-run exposures come from the recording (its sequence
    numbers, at its pace or as fast as the link takes them) instead of a frame-rate timer; each
    software trigger (or pulse) takes the next recorded capture at once, numbered as TRIGGERED said."""

    def __init__(self, source: ReplaySource, produce: Callable[[CaptureRequest], None]):
        super().__init__(produce, source.timebase)
        self.source = source

    def start(self, mode: TriggerMode, fps: int) -> None:
        self.source.restart()
        super().start(mode, fps)

    def close(self) -> None:
        self.source.interrupt()
        super().close()

    def _next_request(self) -> CaptureRequest | None:
        with self._cond:
            if self._closed:
                return None
            if not self._streaming or (self._mode != TriggerMode.FREE_RUN and not self._queue):
                self._cond.wait(0.05)
                return None
            epoch = self.epoch
            trigger = self._queue.popleft() if self._mode != TriggerMode.FREE_RUN else None
        recorded = self.source.next_request(epoch, paced=trigger is None)
        if recorded is None:  # played once to the end: the stream stays started and sends nothing more
            with self._cond:  # (were it stopped, a host would rightly restart it: SPEC §9)
                self._cond.wait(0.05)
            return None
        with self._cond:  # numbers go on rising across streams and modes (SPEC §8.4)
            self.sequence = max(self.sequence, recorded.sequence)
            return self._taken(trigger or recorded)
