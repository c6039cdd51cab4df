"""Pairs whose left and right frames were not taken at the same instant, found by their residuals.

With the final fit, per pair with the board (kept or dropped as an outlier):
  mono_px      the larger of the two views' reprojection RMS, each with its own board pose;
  stereo_px    the right view's RMS when its board pose is the left view's carried through (R, T);
  epipolar_px  RMS of the epipolar error (calib_fit.epipolar_dy);
  motion       how far the board moved between the two frames: the board pose seen by the right
               camera, carried back through (R, T), against the left camera's (centre shift in mm,
               rotation in degrees).
A synchronised pair's one pose serves both views (stereo_px ≈ mono_px, epipolar_px ≈ mono_px); a
pair is reported unsynchronised when stereo_px > max(STEREO_FACTOR · mono_px, mono_px + MIN_EXCESS_PX)
(the board moved in any direction) or epipolar_px > max(EPIPOLAR_FACTOR · mono_px, MIN_EPIPOLAR_PX)
(it moved across the epipolar lines).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from stereocam.tools.calibration.fit import HeadFit, PairPoints, epipolar_dy, rms
from stereocam.tools.calibration.lens import LensSolveError, project, solve_pose

STEREO_FACTOR = 3.0
MIN_EXCESS_PX = 0.5
EPIPOLAR_FACTOR = 2.0
MIN_EPIPOLAR_PX = 0.5


@dataclass(frozen=True)
class PairSync:
    """The residuals of one pair (module docstring), px, and the board's motion between its frames."""

    index: int
    label: str
    mono_px: float
    stereo_px: float
    epipolar_px: float
    motion_mm: float
    motion_deg: float

    @property
    def unsynchronised(self) -> bool:
        return (self.stereo_px > max(STEREO_FACTOR * self.mono_px, self.mono_px + MIN_EXCESS_PX)
                or self.epipolar_px > max(EPIPOLAR_FACTOR * self.mono_px, MIN_EPIPOLAR_PX))


@dataclass(frozen=True)
class SyncReport:
    """Every pair checked and those that look unsynchronised."""

    pairs: list[PairSync]

    @property
    def suspects(self) -> list[PairSync]:
        return [p for p in self.pairs if p.unsynchronised]

    def message(self) -> str | None:
        """What the user is told (None when every pair looks simultaneous)."""
        bad = self.suspects
        if not bad:
            return None
        mm = np.array([p.motion_mm for p in bad])
        deg = np.array([p.motion_deg for p in bad])
        epi = np.median([p.epipolar_px for p in bad])
        mono = np.median([p.mono_px for p in bad])
        names = ", ".join(p.label for p in bad[:12]) + (", ..." if len(bad) > 12 else "")
        return (f"{len(bad)} of {len(self.pairs)} pairs look unsynchronised: the board moved between the left "
                f"and the right frame by {np.median(mm):.1f} mm / {np.median(deg):.2f} deg (median; up to "
                f"{mm.max():.1f} mm / {deg.max():.2f} deg), their epipolar error is {epi:.2f} px against "
                f"{mono:.2f} px reprojection in each view ({names}). Take the pairs simultaneously: "
                f"a synchronised (hardware-triggered) stereo head, the device mode (stereocam calibrate URL), "
                f"or the board held still while each pair is taken")


def _pose(model: str, obj: np.ndarray, pts: np.ndarray, K: np.ndarray, D: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, float]:
    rvec, tvec = solve_pose(model, obj, pts, K, D)
    err = rms(np.linalg.norm(project(model, obj, rvec, tvec, K, D) - pts, axis=1))
    return cv2.Rodrigues(rvec)[0], tvec.ravel(), err


def check_pair(fit: HeadFit, pair: PairPoints) -> PairSync:
    """The residuals and board motion of one pair under `fit`."""
    c, model = fit.calibration, fit.model
    R_l, t_l, e_l = _pose(model, pair.obj, pair.left, c.K_left, c.D_left)
    R_r, t_r, e_r = _pose(model, pair.obj, pair.right, c.K_right, c.D_right)
    carried = project(model, pair.obj, cv2.Rodrigues(c.R @ R_l)[0], c.R @ t_l + c.T, c.K_right, c.D_right)
    stereo = rms(np.linalg.norm(carried - pair.right, axis=1))
    centre = pair.obj.reshape(-1, 3).mean(axis=0)
    back_R, back_t = c.R.T @ R_r, c.R.T @ (t_r - c.T)
    shift = np.linalg.norm((back_R @ centre + back_t) - (R_l @ centre + t_l))
    angle = np.degrees(np.linalg.norm(cv2.Rodrigues(back_R @ R_l.T)[0]))
    return PairSync(pair.index, pair.label, max(e_l, e_r), stereo, rms(epipolar_dy(fit, pair.left, pair.right)),
                    float(shift * 1000), float(angle))


def check_sync(fit: HeadFit, pairs: Sequence[PairPoints]) -> SyncReport:
    """check_pair for every pair whose board pose can be solved."""
    out = []
    for pair in pairs:
        try:
            out.append(check_pair(fit, pair))
        except LensSolveError:
            continue
    return SyncReport(out)
