"""What a user gets: one capture (``Frame``), its status, and how to read its disparity and depth."""
from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.errors import MissingPlaneError


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
    confidence: np.ndarray | None = None  # uint8 per pixel (outputs bit 8, SPEC §5.3): 0 no disparity .. 255

    def __repr__(self) -> str:
        planes = "+".join(n for n, a in (("left", self.left), ("right", self.right), ("disparity", self.disparity),
                                         ("confidence", self.confidence)) if a is not None) or "no planes"
        return (f"Frame(sequence={self.sequence}, {self.width}x{self.height}, {planes}, "
                f"{'rectified' if self.rectified else 'raw'}, status={self.status.value}, "
                f"device_time_us={self.device_time_us})")

    def disparity_plane(self) -> np.ndarray:
        """The ``disparity`` plane as carried (int16 Q4); MissingPlaneError when the frame has none."""
        if self.disparity is None:
            raise MissingPlaneError("this frame carries no disparity (raw frame of an uncalibrated unit or "
                                    "rectify=0, or the outputs config excludes it)")
        return self.disparity

    def disparity_px(self) -> np.ndarray:
        """Disparity in pixels, float32, NaN where invalid."""
        plane = self.disparity_plane()
        d = plane.astype(np.float32) / self.disparity_format.subpixel
        d[plane == self.disparity_format.invalid] = np.nan
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
