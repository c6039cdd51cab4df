"""Stereo calibration data model, its calibration.json form and its binary flash body.

Conventions (the same as OpenCV's):
  * pixel (u, v) = (0, 0) is the centre of the top-left pixel;
  * K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew: a non-zero skew is rejected);
  * D = (k1, k2, p1, p2, k3), the 5-coefficient "plumb bob" model;
  * R, T map a point from the left camera frame to the right one: X_right = R @ X_left + T,
    as cv2.stereoCalibrate defines them; T is in metres (for a right camera to the right of the
    left one, T[0] is about -baseline).

Binary body, format version 1 (little-endian, 248 bytes, no padding). This is what the device
keeps in flash inside a store record (see store.py, which adds the header and the CRC-32):

  offset size type      field
  0      2    u16       body_version (= 1)
  2      2    u16       n_dist (= 5, coefficients per camera)
  4      2    u16       image width  (px) the calibration refers to
  6      2    u16       image height (px)
  8      32   f64[4]    left  fx, fy, cx, cy (px)
  40     40   f64[5]    left  k1, k2, p1, p2, k3
  80     32   f64[4]    right fx, fy, cx, cy (px)
  112    40   f64[5]    right k1, k2, p1, p2, k3
  152    72   f64[9]    R, row-major (left -> right)
  224    24   f64[3]    T (metres, left -> right)
  248                   end

A reader rejects any other body_version, n_dist or length. Floats are IEEE-754 binary64.
"""
from __future__ import annotations

import struct
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from stereocam.protocol.errors import StereoCamError

BODY_VERSION = 1
N_DIST = 5
_HEAD = struct.Struct("<4H")
_BODY = struct.Struct("<4H" + "d" * (4 + 5 + 4 + 5 + 9 + 3))
BODY_SIZE = _BODY.size  # 248

GEOMETRY_KEYS = ("image_size", "K_left", "D_left", "K_right", "D_right", "R", "T")


class CalibrationFormatError(StereoCamError, ValueError):
    """A calibration that is malformed: wrong shapes, non-finite values, bad binary body."""


def _matrix(name: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise CalibrationFormatError(f"{name} is not numeric: {exc}") from None
    if arr.size != int(np.prod(shape)):
        raise CalibrationFormatError(f"{name} must have {int(np.prod(shape))} elements, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise CalibrationFormatError(f"{name} contains non-finite values")
    return arr.reshape(shape)


@dataclass
class CalibrationQuality:
    """Optional quality metrics and status stored next to the geometry in calibration.json."""

    rms_left: float | None = None
    rms_right: float | None = None
    rms_stereo: float | None = None
    epipolar_rms_px: float | None = None
    views_used: int | None = None
    passed: bool | None = None
    written: bool | None = None
    verified: bool | None = None

    @classmethod
    def from_json_dict(cls, d: dict[str, Any]) -> "CalibrationQuality":
        """Pick the quality keys out of a calibration.json dict (missing keys stay None)."""
        return cls(**{f.name: d[f.name] for f in fields(cls) if f.name in d})


@dataclass
class StereoCalibration:
    """One stereo head: both cameras' intrinsics and the left→right extrinsics (see module doc)."""

    image_size: tuple[int, int]
    K_left: np.ndarray
    D_left: np.ndarray
    K_right: np.ndarray
    D_right: np.ndarray
    R: np.ndarray
    T: np.ndarray

    def __post_init__(self) -> None:
        w, h = (int(v) for v in self.image_size)
        if not (0 < w < 65536 and 0 < h < 65536):
            raise CalibrationFormatError(f"image_size must be two integers in 1..65535, got {self.image_size}")
        self.image_size = (w, h)
        for side in ("left", "right"):
            K = _matrix(f"K_{side}", getattr(self, f"K_{side}"), (3, 3))
            if K[0, 1] != 0 or K[1, 0] != 0 or not np.array_equal(K[2], [0.0, 0.0, 1.0]):
                raise CalibrationFormatError(f"K_{side} must be [[fx,0,cx],[0,fy,cy],[0,0,1]], got {K.tolist()}")
            if K[0, 0] <= 0 or K[1, 1] <= 0:
                raise CalibrationFormatError(f"K_{side} focal lengths must be positive")
            setattr(self, f"K_{side}", K)
            setattr(self, f"D_{side}", _matrix(f"D_{side}", getattr(self, f"D_{side}"), (N_DIST,)))
        self.R = _matrix("R", self.R, (3, 3))
        if not np.allclose(self.R @ self.R.T, np.eye(3), atol=1e-6) or np.linalg.det(self.R) <= 0:
            raise CalibrationFormatError("R must be a rotation matrix")
        self.T = _matrix("T", self.T, (3,))

    @property
    def baseline_m(self) -> float:
        """Distance between the two optical centres in metres (= |T|)."""
        return float(np.linalg.norm(self.T))

    def scaled(self, width: int, height: int) -> "StereoCalibration":
        """The same head seen at another output resolution (binning / scaling of the whole frame).

        Pixel centres map as u' = (u + 0.5) * width / W - 0.5, so fx' = fx * sx and
        cx' = (cx + 0.5) * sx - 0.5 (likewise in y); distortion, R and T are unchanged.
        """
        if width <= 0 or height <= 0:
            raise CalibrationFormatError(f"scaled size must be positive, got {width}x{height}")
        sx, sy = width / self.image_size[0], height / self.image_size[1]
        S = np.array([[sx, 0.0, 0.5 * sx - 0.5], [0.0, sy, 0.5 * sy - 0.5], [0.0, 0.0, 1.0]])
        return StereoCalibration((width, height), S @ self.K_left, self.D_left, S @ self.K_right,
                                 self.D_right, self.R, self.T)

    def to_json_dict(self, quality: CalibrationQuality | None = None) -> dict[str, Any]:
        """calibration.json content: geometry keys, then the quality keys that are set."""
        d: dict[str, Any] = {"image_size": list(self.image_size)}
        for key in GEOMETRY_KEYS[1:]:
            d[key] = getattr(self, key).tolist()
        if quality is not None:
            d.update({k: v for k, v in asdict(quality).items() if v is not None})
        return d

    @classmethod
    def from_json_dict(cls, d: dict[str, Any]) -> "StereoCalibration":
        """Parse the geometry keys of a calibration.json dict; extra keys are ignored."""
        missing = [k for k in GEOMETRY_KEYS if k not in d]
        if missing:
            raise CalibrationFormatError(f"calibration.json lacks keys {missing}")
        size = d["image_size"]
        if not (isinstance(size, (list, tuple)) and len(size) == 2):
            raise CalibrationFormatError(f"image_size must be [width, height], got {size!r}")
        return cls(tuple(size), *(d[k] for k in GEOMETRY_KEYS[1:]))

    def to_bytes(self) -> bytes:
        """The binary body described in the module docstring."""
        w, h = self.image_size
        values: list[float] = []
        for K, D in ((self.K_left, self.D_left), (self.K_right, self.D_right)):
            values += [K[0, 0], K[1, 1], K[0, 2], K[1, 2], *D]
        values += [*self.R.reshape(-1), *self.T]
        return _BODY.pack(BODY_VERSION, N_DIST, w, h, *values)

    @classmethod
    def from_bytes(cls, data: bytes) -> "StereoCalibration":
        """Parse a binary body; raises CalibrationFormatError on a wrong version, count or size."""
        if len(data) < _HEAD.size:
            raise CalibrationFormatError(f"calibration body too short: {len(data)} bytes")
        version, n_dist, _, _ = _HEAD.unpack_from(data)
        if version != BODY_VERSION:
            raise CalibrationFormatError(f"unsupported calibration body version {version}")
        if n_dist != N_DIST:
            raise CalibrationFormatError(f"unsupported distortion coefficient count {n_dist}")
        if len(data) != BODY_SIZE:
            raise CalibrationFormatError(f"calibration body must be {BODY_SIZE} bytes, got {len(data)}")
        _, _, w, h, *v = _BODY.unpack(data)

        def K(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
            return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

        return cls((w, h), K(*v[0:4]), v[4:9], K(*v[9:13]), v[13:18], np.reshape(v[18:27], (3, 3)), v[27:30])
