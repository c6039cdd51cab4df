"""Stereo calibration data model, its calibration.json form and its binary flash body.

Conventions (the same as OpenCV's):
  * pixel (u, v) = (0, 0) is the centre of the top-left pixel;
  * K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew: a non-zero skew is rejected);
  * lens model and D, named as ROS camera_info names them:
      plumb_bob            D = (k1, k2, p1, p2, k3)                  OpenCV's standard 5 coefficients
      rational_polynomial  D = (k1, k2, p1, p2, k3, k4, k5, k6)      CALIB_RATIONAL_MODEL
      equidistant          D = (k1, k2, k3, k4)                      cv2.fisheye (θ_d = θ(1+k1θ²+…+k4θ⁸))
  * R, T map a point from the left camera frame to the right one: X_right = R @ X_left + T,
    as cv2.stereoCalibrate defines them; T is in metres (for a right camera to the right of the
    left one, T[0] is about -baseline).

Binary body (little-endian, no padding) — what the device keeps in flash inside a store record
(see store.py, which adds the header and the CRC-32). Format version 2, n = coefficients per camera:

  offset   size   type        field
  0        2      u16         body_version (= 2)
  2        2      u16         n_dist (5 plumb_bob, 8 rational_polynomial, 4 equidistant)
  4        2      u16         image width  (px) the calibration refers to
  6        2      u16         image height (px)
  8        2      u16         lens_model: 0 plumb_bob, 1 rational_polynomial, 2 equidistant
  10       32     f64[4]      left  fx, fy, cx, cy (px)
  42       8n     f64[n]      left  D
  42+8n    32     f64[4]      right fx, fy, cx, cy (px)
  74+8n    8n     f64[n]      right D
  74+16n   72     f64[9]      R, row-major (left -> right)
  146+16n  24     f64[3]      T (metres, left -> right)
  170+16n                     end (250 bytes for plumb_bob)

Format version 1 (248 bytes: no lens_model field, always plumb_bob, so n_dist = 5 and the floats
start at offset 8) is still read. A reader rejects any other body_version, a lens_model it does not
know, an n_dist that does not match the model, or a wrong length: firmware that only knows version 1
refuses a version 2 body at commit (BAD_PAYLOAD) and keeps its calibration. Floats are IEEE-754
binary64.
"""
from __future__ import annotations

import math
import numbers
import struct
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from stereocam.protocol.errors import StereoCamError

BODY_VERSION = 2
LENS_MODELS = ("plumb_bob", "rational_polynomial", "equidistant")  # index = the body's lens_model code
N_DIST = {"plumb_bob": 5, "rational_polynomial": 8, "equidistant": 4}
_HEAD = struct.Struct("<4H")
_V1_BODY = struct.Struct("<4H" + "d" * (4 + 5 + 4 + 5 + 9 + 3))  # 248 bytes


def _v2_body(n: int) -> struct.Struct:
    return struct.Struct("<5H" + "d" * (4 + n + 4 + n + 9 + 3))


def body_size(lens_model: str = "plumb_bob") -> int:
    """Length of a version-2 body for this lens model (250 for plumb_bob)."""
    return _v2_body(N_DIST[lens_model]).size

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


def _image_size(value: Any) -> tuple[int, int]:
    """``value`` as (width, height): two integers (integer-valued floats too) in 1..65535."""
    problem = f"image_size must be two integers in 1..65535, got {value!r}"
    if not isinstance(value, (tuple, list, np.ndarray)) or getattr(value, "ndim", 1) != 1 or len(value) != 2:
        raise CalibrationFormatError(problem)
    size = []
    for v in value:
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real):
            raise CalibrationFormatError(problem)
        if isinstance(v, numbers.Integral):
            size.append(int(v))
        elif math.isfinite(v) and float(v).is_integer():
            size.append(int(float(v)))
        else:
            raise CalibrationFormatError(problem)
    w, h = size
    if not (0 < w < 65536 and 0 < h < 65536):
        raise CalibrationFormatError(problem)
    return w, h


@dataclass
class CalibrationQuality:
    """Optional quality metrics and status stored next to the geometry in calibration.json."""

    rms_left: float | None = None
    rms_right: float | None = None
    rms_stereo: float | None = None
    epipolar_rms_px: float | None = None
    epipolar_all_rms_px: float | None = None
    views_used: int | None = None
    views_dropped: int | None = None
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
    lens_model: str = "plumb_bob"

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Check every field (CalibrationFormatError naming it) and normalise them: image_size to two
        ints, matrices to float64 arrays of their shapes. Serialising calls it again, so a calibration
        changed after construction is checked before it is written anywhere."""
        if not isinstance(self.lens_model, str) or self.lens_model not in N_DIST:
            raise CalibrationFormatError(f"unknown lens model {self.lens_model!r}; known: {', '.join(LENS_MODELS)}")
        n_dist = N_DIST[self.lens_model]
        self.image_size = _image_size(self.image_size)
        for side in ("left", "right"):
            K = _matrix(f"K_{side}", getattr(self, f"K_{side}"), (3, 3))
            if K[0, 1] != 0 or K[1, 0] != 0 or not np.array_equal(K[2], [0.0, 0.0, 1.0]):
                raise CalibrationFormatError(f"K_{side} must be [[fx,0,cx],[0,fy,cy],[0,0,1]], got {K.tolist()}")
            if K[0, 0] <= 0 or K[1, 1] <= 0:
                raise CalibrationFormatError(f"K_{side} focal lengths must be positive")
            setattr(self, f"K_{side}", K)
            setattr(self, f"D_{side}", _matrix(f"D_{side}", getattr(self, f"D_{side}"), (n_dist,)))
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
                                 self.D_right, self.R, self.T, self.lens_model)

    def to_json_dict(self, quality: CalibrationQuality | None = None) -> dict[str, Any]:
        """calibration.json content: geometry keys, then the quality keys that are set."""
        self.validate()
        d: dict[str, Any] = {"image_size": list(self.image_size)}
        for key in GEOMETRY_KEYS[1:]:
            d[key] = getattr(self, key).tolist()
        d["lens_model"] = self.lens_model
        if quality is not None:
            d.update({k: v for k, v in asdict(quality).items() if v is not None})
        return d

    @classmethod
    def from_json_dict(cls, d: dict[str, Any]) -> "StereoCalibration":
        """Parse the geometry keys of a calibration.json dict (lens_model defaults to plumb_bob)."""
        missing = [k for k in GEOMETRY_KEYS if k not in d]
        if missing:
            raise CalibrationFormatError(f"calibration.json lacks keys {missing}")
        size = d["image_size"]
        if not (isinstance(size, (list, tuple)) and len(size) == 2):
            raise CalibrationFormatError(f"image_size must be [width, height], got {size!r}")
        geometry = {k: d[k] for k in GEOMETRY_KEYS[1:]}
        return cls((size[0], size[1]), **geometry, lens_model=d.get("lens_model", "plumb_bob"))

    def to_bytes(self) -> bytes:
        """The version-2 binary body described in the module docstring (the fields checked first)."""
        self.validate()
        w, h = self.image_size
        values: list[float] = []
        for K, D in ((self.K_left, self.D_left), (self.K_right, self.D_right)):
            values += [K[0, 0], K[1, 1], K[0, 2], K[1, 2], *D]
        values += [*self.R.reshape(-1), *self.T]
        n = N_DIST[self.lens_model]
        return _v2_body(n).pack(BODY_VERSION, n, w, h, LENS_MODELS.index(self.lens_model), *values)

    @classmethod
    def from_bytes(cls, data: bytes) -> "StereoCalibration":
        """Parse a binary body (version 1 or 2); CalibrationFormatError on anything else."""
        if len(data) < _HEAD.size + 2:
            raise CalibrationFormatError(f"calibration body too short: {len(data)} bytes")
        version, n_dist, _, _ = _HEAD.unpack_from(data)
        if version == 1:
            model, layout = "plumb_bob", _V1_BODY
        elif version == 2:
            code = struct.unpack_from("<H", data, _HEAD.size)[0]
            if code >= len(LENS_MODELS):
                raise CalibrationFormatError(f"unknown lens model code {code}")
            model = LENS_MODELS[code]
            layout = _v2_body(N_DIST[model])
        else:
            raise CalibrationFormatError(f"unsupported calibration body version {version}")
        if n_dist != N_DIST[model]:
            raise CalibrationFormatError(f"unsupported distortion coefficient count {n_dist} for {model}")
        if len(data) != layout.size:
            raise CalibrationFormatError(f"calibration body must be {layout.size} bytes, got {len(data)}")
        _, _, w, h, *v = layout.unpack(data)
        v = v[1:] if version == 2 else v
        n = n_dist

        def K(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
            return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

        r = 8 + 2 * n
        return cls((w, h), K(*v[0:4]), np.asarray(v[4:4 + n]), K(*v[4 + n:8 + n]), np.asarray(v[8 + n:r]),
                   np.reshape(v[r:r + 9], (3, 3)), np.asarray(v[r + 9:r + 12]), model)
