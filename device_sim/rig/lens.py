"""The lens classes a simulated unit can be built with, and each unit's true calibration for its class.

A lens class is a simulator setting (``SimulatedCamera(lens=...)``, ``sim://?lens=``, ``stereocam sim
--lens``), never a device parameter. The rig renders every view through the true lenses
(calibration/rays.py ``lens_rays``, computed once per format), and the factory flash holds that truth:
  standard  plumb_bob, ~67° across the width (calibration/truth.py: the STOC head);
  wide      rational_polynomial, 120° across the width, a strong barrel a 5-coefficient model misses;
  fisheye   equidistant, 180° across the width (the image corners see ~106° off axis).
Manufacturing variation as truth.py draws it: focal ±3 %, principal point within 2 % of the image,
distortion ±3 % per coefficient, the same rig rotation and baseline. The board fixture holds the
board closer to a shorter lens so it fills a similar share of the image.
"""
from __future__ import annotations

import enum

import numpy as np

from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.errors import ConfigError

from ..calibration.truth import true_calibration

WIDE_D = (2.121, 0.723, 0.0003, -0.0002, 0.098, 0.983, 1.798, 0.025)  # rational: k1 k2 p1 p2 k3 k4 k5 k6
FISHEYE_D = (0.02, -0.004, 0.0005, -0.0001)  # equidistant: k1 k2 k3 k4


class LensClass(str, enum.Enum):
    """Which lenses a simulated unit has."""

    STANDARD = "standard"
    WIDE = "wide"
    FISHEYE = "fisheye"

    @classmethod
    def parse(cls, name: "str | LensClass") -> "LensClass":
        """The lens class called ``name``; ConfigError naming the known ones otherwise."""
        try:
            return cls(name)
        except ValueError:
            raise ConfigError(f"unknown lens class {name!r}; known: {', '.join(c.value for c in cls)}") from None

    @property
    def fov_deg(self) -> float:
        """Nominal field of view across the image width."""
        return {LensClass.STANDARD: 67.4, LensClass.WIDE: 120.0, LensClass.FISHEYE: 180.0}[self]

    @property
    def board_distance_m(self) -> tuple[float, float]:
        """How far the board fixture holds the board (its centre) from the left camera."""
        return {LensClass.STANDARD: (0.45, 1.2), LensClass.WIDE: (0.25, 0.7), LensClass.FISHEYE: (0.18, 0.5)}[self]


def _focal(lens: LensClass, width: int) -> float:
    """Focal length (px) that spans the class's field of view across ``width`` pixels."""
    half = np.radians(lens.fov_deg) / 2
    if lens == LensClass.FISHEYE:
        k1, k2, k3, k4 = FISHEYE_D
        t2 = half * half
        return (width / 2) / (half * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))))
    k1, k2, _, _, k3, k4, k5, k6 = WIDE_D
    r2 = np.tan(half) ** 2
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    return float((width / 2) / (np.tan(half) * radial))


def lens_calibration(seed: int, lens: LensClass | str = LensClass.STANDARD,
                     sensor_size: tuple[int, int] = (1280, 960)) -> StereoCalibration:
    """The true calibration of the unit with this seed and lens class (same inputs → same unit)."""
    lens = LensClass.parse(lens)
    base = true_calibration(seed, sensor_size)
    if lens == LensClass.STANDARD:
        return base
    width, height = sensor_size
    rng = np.random.default_rng([0x1E45, int(seed), list(LensClass).index(lens)])
    nominal = np.array(WIDE_D if lens == LensClass.WIDE else FISHEYE_D)
    cams = []
    for _ in range(2):
        f = _focal(lens, width) * (1.0 + rng.uniform(-0.03, 0.03))
        cx = (width - 1) / 2 + rng.uniform(-0.02, 0.02) * width
        fy = f * (1.0 + rng.uniform(-0.003, 0.003))
        K = np.array([[f, 0.0, cx], [0.0, fy, (height - 1) / 2 + rng.uniform(-0.02, 0.02) * height], [0.0, 0.0, 1.0]])
        cams.append((K, nominal * (1.0 + rng.uniform(-0.03, 0.03, nominal.size))))
    model = "rational_polynomial" if lens == LensClass.WIDE else "equidistant"
    return StereoCalibration(sensor_size, cams[0][0], cams[0][1], cams[1][0], cams[1][1], base.R, base.T, model)
