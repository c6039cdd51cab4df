"""Each simulated unit's true calibration, drawn reproducibly from its seed.

The numbers model manufacturing variation of a 1280x960 STOC-class head with a nominal focal
length of 960 px: focal length within ±3 % (fx and fy differ by up to ±0.3 %), principal points
off-centre by up to 2 % of the image size, radial distortion k1 in [-0.1, 0.05], small k2/k3,
tangential p1/p2 of order 1e-3, a baseline of 6-12 cm and a relative rotation under 1°.
"""
from __future__ import annotations

import numpy as np

from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.rectification import rodrigues

NOMINAL_FOCAL_PX = 960.0
NOMINAL_WIDTH = 1280


def _camera(rng: np.random.Generator, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    f = NOMINAL_FOCAL_PX * width / NOMINAL_WIDTH * (1.0 + rng.uniform(-0.03, 0.03))
    fx, fy = f, f * (1.0 + rng.uniform(-0.003, 0.003))
    cx = (width - 1) / 2 + rng.uniform(-0.02, 0.02) * width
    cy = (height - 1) / 2 + rng.uniform(-0.02, 0.02) * height
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    D = np.array([rng.uniform(-0.1, 0.05), rng.uniform(-0.02, 0.02),
                  rng.uniform(-1.5e-3, 1.5e-3), rng.uniform(-1.5e-3, 1.5e-3), rng.uniform(-0.005, 0.005)])
    return K, D


def true_calibration(seed: int, sensor_size: tuple[int, int] = (1280, 960)) -> StereoCalibration:
    """The true calibration of the unit with this seed (same seed → same unit)."""
    width, height = sensor_size
    if width <= 0 or height <= 0:
        raise ValueError(f"sensor_size must be positive, got {sensor_size}")
    rng = np.random.default_rng([0x5CA1, int(seed)])
    K_left, D_left = _camera(rng, width, height)
    K_right, D_right = _camera(rng, width, height)
    R = rodrigues(np.deg2rad(rng.uniform(-0.5, 0.5, size=3)))  # |angle| < 0.87°
    baseline = rng.uniform(0.06, 0.12)
    centre_right = np.array([baseline, rng.uniform(-1e-3, 1e-3), rng.uniform(-1e-3, 1e-3)])
    centre_right *= baseline / np.linalg.norm(centre_right)
    T = -R @ centre_right  # X_right = R (X_left - C_right)
    return StereoCalibration((width, height), K_left, D_left, K_right, D_right, R, T)
