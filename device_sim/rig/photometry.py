"""How a scene class's light reaches each imager beyond the shared exposure: a gain/exposure and
black-level mismatch of the right eye, vignetting, a noise level and motion blur (the exposure
window the moving primitives are integrated over). The default changes nothing."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BLUR_SAMPLES = 9  # sub-instants a blurred exposure averages


@dataclass(frozen=True)
class Photometry:
    """Per-scene photometric settings (radiance is 0..1 before the sensor's exposure scale)."""

    light: float = 1.0  # scene brightness, both eyes (a dim scene needs gain: more noise per DN)
    right_gain: float = 1.0  # right imager's response relative to the left (exposure or gain mismatch)
    right_offset: float = 0.0  # right imager's black-level offset, in radiance units (1/255 ~ 1 DN)
    vignetting: float = 0.0  # fraction of light lost in the image corners (quadratic in radius)
    noise: float = 1.0  # multiplier on the sensor's shot and read noise
    blur_s: float = 0.0  # exposure window (s) moving primitives are integrated over, centred on t

    def instants(self, t: float) -> np.ndarray:
        """Scene times one exposure at ``t`` averages: ``t`` alone, or ``BLUR_SAMPLES`` across the window."""
        if self.blur_s <= 0:
            return np.array([t])
        return t + self.blur_s * (np.arange(BLUR_SAMPLES) / (BLUR_SAMPLES - 1) - 0.5)

    def apply(self, radiance: np.ndarray, rays: np.ndarray, eye: int) -> np.ndarray:
        """Radiance of ``eye`` (0 left, 1 right) after light level, vignetting and the eye's gain
        and offset; ``rays`` (H, W, 3) are that eye's camera-frame pixel rays (z = 1)."""
        out = radiance * np.float32(self.light)
        if self.vignetting > 0:
            rho2 = rays[..., 0] ** 2 + rays[..., 1] ** 2
            out *= (1.0 - self.vignetting * rho2 / rho2.max()).astype(np.float32)
        if eye == 1 and (self.right_gain != 1.0 or self.right_offset != 0.0):
            out = out * np.float32(self.right_gain) + np.float32(self.right_offset)
        return np.ascontiguousarray(out, np.float32)


PLAIN = Photometry()
