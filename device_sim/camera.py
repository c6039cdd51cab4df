"""The simulated firmware: decodes requests, dispatches them, streams captures.

Bytes in through ``receive``; bytes out through the sink given to ``attach``. Every transport
(in-process, pty, TCP, USB) drives this one object, so they all run the same firmware.
"""
from __future__ import annotations

import collections
import logging
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from stereocam.protocol import messages as m
from stereocam.protocol.errors import DeviceError, ErrorCode, ProtocolError
from stereocam.protocol.framing import FLAG_RESEND, MAX_PAYLOAD, VERSION_MAJOR, VERSION_MINOR, Decoder, Packet
from stereocam.protocol.params import BY_NAME, Output, TriggerMode

from . import registry
from .capture import CaptureEngine, CaptureRequest
from .clock import DeviceClock
from .config_store import ConfigStore
from .matching import Matcher, MatchParams, from_config
from .matching import warm_up as matching_warm_up
from .calib_service import CalibrationService
from stereocam.protocol.calibration import StereoCalibration
from .calibration.truth import true_calibration
from .scene import BOARD_SCENE
from .sensor import SENSOR_H, SENSOR_W, Geometry, SensorRig
from .replay import ReplayEngine, ReplaySource
from .trigger import TriggerLine

MODEL = "STOC-SIM"
FIRMWARE_VERSION = "1.1.0"
CHUNK = 128 * 1024  # FRAME_DATA payload bytes per message
CAPABILITIES = (m.Capability.DISPARITY | m.Capability.SOFTWARE_TRIGGER | m.Capability.EXTERNAL_TRIGGER
                | m.Capability.TIME_SYNC | m.Capability.CALIBRATION)
RESEND_CACHE = 64
GROUND_TRUTH_KEEP = 64

Sink = Callable[[bytes], None]
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class _Exposure:
    """What the simulator needs to reconstruct the truth of one capture on demand."""

    sequence: int
    host_monotonic: float
    scene_time: float
    scene: int
    rays: np.ndarray  # camera-frame rays of the delivered left image (rectified pinhole or raw lens)
    rot: np.ndarray  # that view's camera→world rotation
    focal_px: float
    baseline_m: float


@dataclass(frozen=True)
class GroundTruth:
    """What the simulator knows about one capture, for the delivered left image's pixels."""

    sequence: int
    host_monotonic: float  # the exposure instant on the host's monotonic clock
    depth_m: np.ndarray  # along the delivered view's optical axis; inf where nothing was hit
    disparity_px: np.ndarray  # f * B / z for rectified frames, 0 where nothing was hit (or raw)


class SimulatedCamera:
    """One simulated STOC-class unit (firmware + sensor rig)."""

    def __init__(self, serial: str | None = None, seed: int = 0, trigger_line: TriggerLine | None = None,
                 flash_path: str | Path | None = None, factory_calibrated: bool = True,
                 source: ReplaySource | None = None):
        """``flash_path``: the file behind this unit's flash (kept across runs); None: a private
        temporary file. ``factory_calibrated``: the unit left the factory with its true calibration
        stored (False: fresh from assembly, streams raw images until calibrated). ``source``: a
        recording that stands in for the sensor rig (its unit's identity, calibration, configuration)."""
        self.seed = seed
        self.source = source
        self.serial = source.serial if source else serial or f"SIM{seed:05d}"
        self.model = source.model if source else MODEL
        self.firmware_version = source.firmware_version if source else FIRMWARE_VERSION
        self.clock = source.clock if source else DeviceClock(seed)
        self.config = ConfigStore()
        self._truth_cal = true_calibration(seed)
        if source:
            self.config.apply({BY_NAME[k].pid: v for k, v in source.config.items() if k in BY_NAME}, False)
            factory_calibrated = source.calibration is not None
            self._truth_cal = source.calibration or self._truth_cal
        self.rig = SensorRig(seed, self._truth_cal)
        self._tmpdir = None
        if flash_path is None:
            self._tmpdir = tempfile.TemporaryDirectory(prefix="stereocam-flash-")
            flash_path = Path(self._tmpdir.name) / f"{self.serial}.flash"
        self.calibration = CalibrationService(flash_path, self._truth_cal, factory_calibrated)
        self.decoder = Decoder()
        self.counters: collections.Counter[str] = collections.Counter()
        self._sink: Sink | None = None
        self._sink_lock = threading.Lock()
        self._rx_lock = threading.Lock()
        self._replies: collections.OrderedDict[int, tuple[int, bytes]] = collections.OrderedDict()
        self._truth: collections.OrderedDict[int, _Exposure] = collections.OrderedDict()
        self._view_rays: dict[Geometry, np.ndarray] = {}
        self._matcher: Matcher | None = None
        self._last_rx = time.monotonic()
        self._soft_triggers = 0
        self.engine = ReplayEngine(source, self._produce, self._watchdog) if source else \
            CaptureEngine(self._produce, self._watchdog)
        self.trigger_line = trigger_line
        if trigger_line is not None:
            trigger_line.attach(self._on_pulse)
        self._handlers: dict[int, Callable[[m.Message], m.Message]] = {
            m.MsgType.GET_INFO: self._get_info, m.MsgType.GET_CONFIG: self._get_config,
            m.MsgType.SET_CONFIG: self._set_config, m.MsgType.TRIGGER: self._trigger,
            m.MsgType.START: self._start, m.MsgType.STOP: self._stop,
            m.MsgType.HEARTBEAT: self._heartbeat, m.MsgType.TIME_SYNC: self._time_sync,
            m.MsgType.CALIB_READ: self.calibration.read, m.MsgType.CALIB_WRITE: self.calibration.write,
            m.MsgType.CALIB_COMMIT: self.calibration.commit,
            m.MsgType.CALIB_RESTORE: lambda _: self.calibration.restore_factory(),
        }
        self._boot()
        registry.register(self)

    def _boot(self) -> None:
        """What firmware does before it answers: compile (or load from numba's cache) every kernel
        of the capture path, so the first frames are not stalled. Paid once per process."""
        matching_warm_up()
        self.rig.set_format(64, 48)  # a tiny format: the real one is set by the first capture
        left, right = self.rig.capture(0.0, 0, 4000, 0, 0)
        maps, _ = self.calibration.maps(64, 48)
        if maps is not None:
            maps.rectify(left, right)

    # -- byte interface ---------------------------------------------------------------------
    def attach(self, sink: Sink) -> None:
        """Send all further output to ``sink`` (called from device threads; may block)."""
        with self._sink_lock:
            self._sink = sink
        with self._rx_lock:  # a new host: its request ids say nothing about the last one's
            self._replies.clear()
            self.decoder = Decoder(stats=self.decoder.stats)
        self._last_rx = time.monotonic()

    @property
    def attached(self) -> bool:
        """Whether a host link (in-process pipe, pty, socket, USB) currently holds this unit."""
        return self._sink is not None

    def detach(self) -> None:
        """The host link is gone: output is discarded and streaming stops."""
        with self._sink_lock:
            self._sink = None
        self.engine.stop()

    def receive(self, data: bytes) -> None:
        """Bytes from the host; replies go to the sink before this returns."""
        with self._rx_lock:
            packets = self.decoder.feed(data)
            for packet in packets:
                self._last_rx = time.monotonic()
                wire = self._dispatch(packet)
                with self._sink_lock:
                    self._emit(wire)

    def close(self) -> None:
        registry.unregister(self)
        self.engine.close()
        if self.trigger_line is not None:
            self.trigger_line.detach(self._on_pulse)
        with self._sink_lock:
            self._sink = None
        if self._tmpdir is not None:
            self._tmpdir.cleanup()
        if self.source is not None:
            self.source.close()

    def true_calibration(self) -> StereoCalibration:
        """This unit's true calibration (full sensor resolution), as the calibration tool writes it."""
        return self._truth_cal

    def __enter__(self) -> "SimulatedCamera":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- dispatch ---------------------------------------------------------------------------
    def _dispatch(self, packet: Packet) -> bytes:
        rid = packet.request_id
        cached = self._replies.get(rid)
        if packet.flags & FLAG_RESEND and cached is not None and cached[0] == packet.msg_type:
            self.counters["resends_replayed"] += 1
            return cached[1]
        handler = self._handlers.get(packet.msg_type)
        if handler is None:
            reply: m.Message = self._nack(packet.msg_type, ErrorCode.UNKNOWN_TYPE,
                                          f"unknown request type 0x{packet.msg_type:04x}")
        else:
            try:
                reply = handler(m.decode_packet(packet))
            except ProtocolError as exc:
                reply = self._nack(packet.msg_type, ErrorCode.BAD_PAYLOAD, str(exc))
            except DeviceError as exc:  # a handler's refusal: the state it guards is unchanged
                pid = BY_NAME[exc.param].pid if exc.param in BY_NAME else 0
                reply = self._nack(packet.msg_type, ErrorCode(exc.code), exc.device_message, pid)
            except Exception as exc:  # a firmware bug still answers, so the host never just times out
                log.exception("handler for 0x%04x failed", packet.msg_type)
                reply = self._nack(packet.msg_type, ErrorCode.INTERNAL, f"{type(exc).__name__}: {exc}")
        wire = m.encode(reply, rid)
        self._replies[rid] = (packet.msg_type, wire)
        self._replies.move_to_end(rid)
        while len(self._replies) > RESEND_CACHE:
            self._replies.popitem(last=False)
        return wire

    def _nack(self, request_type: int, code: ErrorCode, text: str, param_id: int = 0) -> m.Nack:
        self.counters["nacks"] += 1
        return m.Nack(request_type, code, param_id, text)

    def _emit(self, wire: bytes) -> bool:
        """Write under ``_sink_lock``; a failing sink means the link is gone: detach and stop."""
        if self._sink is None:
            return False
        try:
            self._sink(wire)
            return True
        except OSError:
            self._sink = None
            self.engine.stop()
            return False

    # -- handlers ---------------------------------------------------------------------------
    def _get_info(self, _: m.Message) -> m.Info:
        return m.Info(self.model, self.serial, self.firmware_version, (VERSION_MAJOR, VERSION_MINOR), CAPABILITIES,
                      SENSOR_W, SENSOR_H, MAX_PAYLOAD, BY_NAME["width"].hi, BY_NAME["height"].hi,
                      self.calibration.calibration_id)

    def _get_config(self, _: m.Message) -> m.Config:
        return m.Config(self.config.by_id())

    def _set_config(self, msg: m.SetConfig) -> m.Message:
        rej = self.config.apply(msg.values, self.engine.streaming)
        if rej:
            return self._nack(msg.TYPE, rej.code, rej.message, rej.param_id)
        self.engine.set_rate(self.config.snapshot()["fps"])
        return m.ConfigApplied(self.config.by_id())

    def _trigger(self, msg: m.Trigger) -> m.Message:
        cfg = self.config.snapshot()
        if cfg["trigger_mode"] != TriggerMode.SOFTWARE:
            return self._nack(msg.TYPE, ErrorCode.BAD_STATE, "software trigger needs trigger_mode=software",
                              BY_NAME["trigger_mode"].pid)
        if not self.engine.streaming:
            return self._nack(msg.TYPE, ErrorCode.BAD_STATE, "software trigger needs a started stream")
        req = self.engine.trigger(self._soft_triggers + 1, TriggerMode.SOFTWARE)
        if req is None:
            return self._nack(msg.TYPE, ErrorCode.BUSY, "trigger queue full; previous captures still pending")
        self._soft_triggers += 1
        self.counters["triggers"] += 1
        return m.Triggered(req.trigger_id, req.sequence)

    def _on_pulse(self, trigger_id: int) -> None:
        if self.config.snapshot()["trigger_mode"] == TriggerMode.EXTERNAL and self.engine.streaming:
            self.counters["triggers"] += 1
            self.engine.trigger(trigger_id, TriggerMode.EXTERNAL)

    def _start(self, _: m.Message) -> m.Started:
        cfg = self.config.snapshot()
        if not self.engine.streaming:
            self.engine.start(TriggerMode(cfg["trigger_mode"]), cfg["fps"])
        return m.Started()

    def _stop(self, _: m.Message) -> m.Stopped:
        self.engine.stop()
        return m.Stopped()

    def _heartbeat(self, _: m.Message) -> m.Status:
        return m.Status(self.clock.uptime_us(), self.engine.streaming,
                        self.config.snapshot()["trigger_mode"], self.status_counters())

    def _time_sync(self, _: m.Message) -> m.Time:
        return m.Time(self.clock.now_us())

    def status_counters(self) -> dict[str, int]:
        st = self.decoder.stats
        c = dict(self.counters)
        c.update(frames_captured=self.engine.captured, frames_dropped=self.engine.dropped,
                 rx_bytes=st.bytes_in, rx_packets=st.packets, rx_garbage_bytes=st.garbage_bytes,
                 rx_header_crc_errors=st.header_crc_errors + st.bad_headers,
                 rx_payload_crc_errors=st.payload_crc_errors, rx_oversize=st.oversize,
                 rx_unsupported_version=st.unsupported_version)
        return c

    # -- streaming --------------------------------------------------------------------------
    def _watchdog(self) -> None:
        timeout_ms = self.config.snapshot()["heartbeat_timeout_ms"]
        if self.engine.streaming and timeout_ms and time.monotonic() - self._last_rx > timeout_ms / 1000:
            self.counters["heartbeat_timeouts"] += 1
            self.engine.stop()

    def _match_params(self, cfg: dict[str, int]) -> MatchParams:
        return from_config(cfg)

    def _disparity(self, cfg: dict[str, int], left: np.ndarray, right: np.ndarray) -> np.ndarray:
        params = self._match_params(cfg)
        if self._matcher is None or self._matcher.params != params or self._matcher.shape != left.shape:
            self._matcher = Matcher(left.shape, params)
        return self._matcher.match(left, right)

    def _produce(self, req: CaptureRequest) -> None:
        cfg = self.config.snapshot()
        if self.source is not None:
            replayed = self.source.capture(req, cfg, self._disparity)
            return self._send_capture(req, replayed.begin, replayed.planes)
        w, h = cfg["width"], cfg["height"]
        self.rig.set_format(w, h)
        t = req.time - self.clock.boot
        left, right = self.rig.capture(t, cfg["scene"], cfg["exposure_us"], cfg["gain"],
                                       req.sequence ^ (self.seed << 20))
        maps, calib_id = self.calibration.maps(w, h)
        if not cfg["rectify"]:
            maps = None
        outputs = Output(cfg["outputs"])
        if maps is not None:  # on-board rectification from the stored calibration
            left, right = maps.rectify(left, right)
            g = maps.geometry
            focal, cx, cy, baseline = g.focal_px, g.cx, g.cy, g.baseline_m
            view = Geometry(w, h, focal, cx, cy, baseline)
            if view not in self._view_rays:
                self._view_rays = {view: view.rays()}  # one table per rectified view, not per frame
            self._remember(req, cfg["scene"], t, self._view_rays[view], g.R1.T, focal, baseline)
            flags = m.FRAME_RECTIFIED
        else:  # raw images: no disparity without a calibration
            outputs &= ~Output.DISPARITY
            focal = cx = cy = baseline = 0.0
            self._remember(req, cfg["scene"], t, self.rig._rays[0], np.eye(3), 0.0, 0.0)
            flags = 0
        disp = self._disparity(cfg, left, right) if Output.DISPARITY in outputs else None
        begin = m.FrameBegin(
            req.sequence & 0xFFFFFFFF, req.trigger_id & 0xFFFFFFFF, self.clock.at(req.time), cfg["exposure_us"],
            cfg["gain"], w, h, int(outputs), flags, m.DISPARITY_S16_Q4, 16, cfg["min_disparity"],
            cfg["num_disparities"], (cfg["min_disparity"] - 1) * 16, calib_id,
            focal, cx, cy, baseline)
        planes = {Output.LEFT: left, Output.RIGHT: right, Output.DISPARITY: disp}
        self._send_capture(req, begin, {p: img for p, img in planes.items() if p in outputs})

    def _send_capture(self, req: CaptureRequest, begin: m.FrameBegin, planes: dict[Output, np.ndarray]) -> None:
        """FRAME_BEGIN, the ``planes`` in FRAME_DATA chunks, FRAME_END."""
        sizes = {}
        if not self._send_frame_part(req, m.encode(begin)):
            return
        for plane in (Output.LEFT, Output.RIGHT, Output.DISPARITY):
            sizes[plane] = 0
            img = planes.get(plane)
            if img is None:
                continue
            raw = memoryview(np.ascontiguousarray(img, dtype=img.dtype.newbyteorder("<"))).cast("B")
            for off in range(0, len(raw), CHUNK):
                if not self._send_frame_part(req, m.encode(m.FrameData(req.sequence, int(plane), off,
                                                                       raw[off:off + CHUNK]))):
                    return
            sizes[plane] = len(raw)
        if not self._send_frame_part(req, m.encode(m.FrameEnd(req.sequence, m.FRAME_OK, sizes[Output.LEFT],
                                                              sizes[Output.RIGHT], sizes[Output.DISPARITY]))):
            return
        self.counters["frames_sent"] += 1

    def _send_frame_part(self, req: CaptureRequest, wire: bytes) -> bool:
        """One message of a capture. The sink is taken per message, not per capture, so a reply
        waits for at most one chunk on a slow link; a capture whose stream was stopped meanwhile
        is cut off (the host counts it incomplete and forgets it at the next start)."""
        with self._sink_lock:
            return self.engine.current(req) and self._emit(wire)

    def _remember(self, req: CaptureRequest, scene_id: int, t: float, rays: np.ndarray, rot: np.ndarray,
                  focal: float, baseline: float) -> None:
        self._truth[req.sequence] = _Exposure(req.sequence, req.time, t, scene_id, rays, rot, focal, baseline)
        while len(self._truth) > GROUND_TRUTH_KEEP:
            self._truth.popitem(last=False)

    def ground_truth(self, sequence: int) -> GroundTruth | None:
        """Truth for one of the last few captures (None once it has aged out), rendered on demand
        for exactly the view the frame delivered (rectified by the stored calibration, or raw)."""
        e = self._truth.get(sequence)
        if e is None or e.scene == BOARD_SCENE:
            return None
        depth = self.rig.depth(e.scene_time, e.scene, e.rays, e.rot)
        with np.errstate(divide="ignore"):
            disp = np.where(np.isfinite(depth) & (e.focal_px > 0), e.focal_px * e.baseline_m / depth, 0)
        return GroundTruth(sequence, e.host_monotonic, depth, disp.astype(np.float32))
