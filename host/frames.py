"""Frames: the typed capture a user gets, and the assembler that builds them from the stream.

FRAME_BEGIN opens a capture, FRAME_DATA chunks fill its planes, FRAME_END closes it. A capture
with a missing chunk, a chunk outside its plane or a byte count that disagrees with the trailer is
dropped and counted by reason; a gap in sequence numbers is counted as lost. Nothing is hidden.
"""
from __future__ import annotations

import collections
import enum
import logging
import queue
from dataclasses import dataclass, field

import numpy as np

from stereocam.protocol import messages as m
from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.params import Output
from stereocam.protocol.segmentation import PLANE_DTYPE, plane_size, planes_of


class FrameStatus(enum.Enum):
    COMPLETE = "complete"
    MISSING_DATA = "missing data"  # a chunk or the trailer never arrived; missing bytes read as 0
    SIZE_MISMATCH = "size mismatch"  # a chunk outside its plane, or the trailer disagrees
    DEVICE_ERROR = "device error"  # the device flagged the capture in its trailer


@dataclass(frozen=True)
class DisparityFormat:
    """How to read ``Frame.disparity``: value = disparity * subpixel; ``invalid`` marks no match."""

    subpixel: int
    min_disparity: int
    num_disparities: int
    invalid: int


@dataclass(frozen=True)
class StereoGeometry:
    """Rectified geometry that turns disparity (px) into depth (m): Z = f * B / d."""

    focal_px: float
    cx: float
    cy: float
    baseline_m: float
    calibration_id: int = 0

    @property
    def Q(self) -> np.ndarray:
        """OpenCV's 4x4 reprojection matrix (cv2.reprojectImageTo3D), both principal points equal."""
        return np.array([[1, 0, 0, -self.cx], [0, 1, 0, -self.cy], [0, 0, 0, self.focal_px],
                         [0, 0, 1.0 / self.baseline_m, 0]], dtype=np.float64)


@dataclass
class Frame:
    """One capture: both images and the disparity share one sequence number."""

    sequence: int
    trigger_id: int
    device_time_us: int
    host_time: float  # device time mapped to the host's time.monotonic() clock
    left: np.ndarray | None
    right: np.ndarray | None
    disparity: np.ndarray | None  # int16, disparity * 16, invalid = (min_disparity - 1) * 16
    exposure_us: int
    gain: int
    width: int
    height: int
    rectified: bool
    disparity_format: DisparityFormat
    geometry: StereoGeometry  # from the calibration the host read from the device (see Camera)
    status: FrameStatus = FrameStatus.COMPLETE
    calibration: StereoCalibration | None = None  # that calibration, scaled to this frame's size

    def __repr__(self) -> str:
        planes = "+".join(n for n, a in (("left", self.left), ("right", self.right), ("disparity", self.disparity))
                          if a is not None) or "no planes"
        return (f"Frame(sequence={self.sequence}, {self.width}x{self.height}, {planes}, "
                f"{'rectified' if self.rectified else 'raw'}, status={self.status.value}, "
                f"device_time_us={self.device_time_us})")

    def disparity_px(self) -> np.ndarray:
        """Disparity in pixels, float32, NaN where invalid."""
        if self.disparity is None:
            raise ValueError("this frame carries no disparity (raw frame of an uncalibrated unit or "
                             "rectify=0, or the outputs config excludes it)")
        d = self.disparity.astype(np.float32) / self.disparity_format.subpixel
        d[self.disparity == self.disparity_format.invalid] = np.nan
        return d

    def depth(self) -> np.ndarray:
        """Depth along the optical axis in metres, float32, NaN where unknown."""
        d = self.disparity_px()
        g = self.geometry
        with np.errstate(divide="ignore", invalid="ignore"):
            z = (g.focal_px * g.baseline_m) / d
        z[~(d > 0)] = np.nan
        return z

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """Valid 3-D points (N x 3, metres, left camera frame) and their grey levels (N,)."""
        z = self.depth()
        h, w = z.shape
        g = self.geometry
        ys, xs = np.nonzero(np.isfinite(z))
        zz = z[ys, xs]
        pts = np.stack([(xs - g.cx) * zz / g.focal_px, (ys - g.cy) * zz / g.focal_px, zz], axis=1)
        grey = self.left[ys, xs] if self.left is not None else np.full(len(zz), 255, np.uint8)
        return pts.astype(np.float32), grey


@dataclass
class AssemblyStats:
    frames: int = 0
    incomplete: int = 0  # a chunk or the trailer never arrived
    size_mismatch: int = 0  # chunk outside its plane or trailer disagrees
    device_errors: int = 0  # the device's trailer status was not OK
    orphan_chunks: int = 0  # chunks of a capture whose leader was lost
    lost: int = 0  # sequence numbers never seen (dropped on the device or on the link)
    queue_overflow: int = 0  # delivered frames discarded because the user did not keep up

    @property
    def dropped(self) -> int:
        """Captures the user did not get whole (delivered flawed ones included)."""
        return self.incomplete + self.size_mismatch + self.device_errors + self.lost + self.queue_overflow


_log = logging.getLogger(__name__)


@dataclass
class _Building:
    begin: m.FrameBegin
    buffers: dict[int, bytearray]
    received: dict[int, int] = field(default_factory=lambda: collections.defaultdict(int))
    bad: bool = False


class FrameAssembler:
    """Consumes frame messages in order; puts Frames on a bounded queue (oldest dropped).

    Flawed captures are counted by reason and dropped, or, with ``deliver_incomplete``, delivered
    with their ``status`` set (as GigE/USB3 Vision SDKs hand out buffers marked incomplete).
    """

    def __init__(self, clock_map, depth: int = 8, deliver_incomplete: bool = False):
        self.deliver_incomplete = deliver_incomplete
        self.frames: queue.Queue[Frame] = queue.Queue(maxsize=depth)
        self.stats = AssemblyStats()
        self._clock_map = clock_map
        self._cur: _Building | None = None
        self._last_seq: int | None = None

    def reset(self) -> None:
        """Before a new stream: forget the last sequence (a gap across start is no loss), a capture
        cut off by the stop, and the frames still queued."""
        self._last_seq = None
        self._cur = None
        while True:
            try:
                self.frames.get_nowait()
            except queue.Empty:
                return

    def on_message(self, msg: m.Message) -> None:
        if isinstance(msg, m.FrameBegin):
            self._begin(msg)
        elif isinstance(msg, m.FrameData):
            self._data(msg)
        elif isinstance(msg, m.FrameEnd):
            self._end(msg)

    def _begin(self, b: m.FrameBegin) -> None:
        if self._cur is not None:  # its FRAME_END never came
            self._flawed(self._cur, FrameStatus.MISSING_DATA)
        if self._last_seq is not None and b.sequence > self._last_seq + 1:
            self.stats.lost += b.sequence - self._last_seq - 1
            _log.info("frames %d..%d lost (never seen on the link)", self._last_seq + 1, b.sequence - 1)
        self._last_seq = b.sequence
        self._cur = _Building(b, {p: bytearray(plane_size(p, b.width, b.height)) for p in planes_of(b)})

    def _data(self, d: m.FrameData) -> None:
        cur = self._cur
        if cur is None or cur.begin.sequence != d.sequence:
            self.stats.orphan_chunks += 1
            return
        buf = cur.buffers.get(d.plane)
        if buf is None or d.offset + len(d.data) > len(buf):
            cur.bad = True
            return
        buf[d.offset:d.offset + len(d.data)] = d.data
        cur.received[d.plane] += len(d.data)

    def _end(self, e: m.FrameEnd) -> None:
        cur, self._cur = self._cur, None
        if cur is None or cur.begin.sequence != e.sequence:
            if cur is not None:
                self._flawed(cur, FrameStatus.MISSING_DATA)
            return
        sent = {Output.LEFT: e.left_bytes, Output.RIGHT: e.right_bytes, Output.DISPARITY: e.disparity_bytes}
        if e.status != m.FRAME_OK:
            self._flawed(cur, FrameStatus.DEVICE_ERROR)
        elif cur.bad or any(sent[p] != len(buf) for p, buf in cur.buffers.items()):
            self._flawed(cur, FrameStatus.SIZE_MISMATCH)
        elif any(cur.received[p] != len(buf) for p, buf in cur.buffers.items()):
            self._flawed(cur, FrameStatus.MISSING_DATA)
        else:
            self._deliver(self._frame(cur, FrameStatus.COMPLETE))

    def _flawed(self, cur: _Building, status: FrameStatus) -> None:
        counter = {FrameStatus.MISSING_DATA: "incomplete", FrameStatus.SIZE_MISMATCH: "size_mismatch",
                   FrameStatus.DEVICE_ERROR: "device_errors"}[status]
        setattr(self.stats, counter, getattr(self.stats, counter) + 1)
        _log.info("frame %d dropped: %s", cur.begin.sequence, status.value)
        if self.deliver_incomplete:
            self._deliver(self._frame(cur, status))

    def _frame(self, cur: _Building, status: FrameStatus) -> Frame:
        b = cur.begin
        planes = {p: np.frombuffer(buf, dtype=PLANE_DTYPE[p]).reshape(b.height, b.width)
                  for p, buf in cur.buffers.items()}
        disp = planes.get(Output.DISPARITY)
        return Frame(
            b.sequence, b.trigger_id, b.device_time_us, self._clock_map.to_host(b.device_time_us),
            planes.get(Output.LEFT), planes.get(Output.RIGHT),
            disp.astype(np.int16, copy=False) if disp is not None else None, b.exposure_us, b.gain,
            b.width, b.height, bool(b.flags & m.FRAME_RECTIFIED),
            DisparityFormat(b.subpixel, b.min_disparity, b.num_disparities, b.invalid_disparity),
            StereoGeometry(b.focal_px, b.cx, b.cy, b.baseline_m, b.calibration_id), status)

    def _deliver(self, frame: Frame) -> None:
        self.stats.frames += frame.status is FrameStatus.COMPLETE
        while True:
            try:
                self.frames.put_nowait(frame)
                return
            except queue.Full:
                try:
                    old = self.frames.get_nowait()
                    self.stats.queue_overflow += 1
                    _log.debug("frame %d discarded: the user did not take it before the queue filled", old.sequence)
                except queue.Empty:
                    pass
