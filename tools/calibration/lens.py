"""Lens models for the calibration tool: one interface over OpenCV's pinhole and fisheye solvers.

  plumb_bob            cv2.calibrateCamera, 5 coefficients (k1, k2, p1, p2, k3)
  rational_polynomial  cv2.calibrateCamera with CALIB_RATIONAL_MODEL, 8 coefficients, started from
                       the plumb_bob fit (started cold it diverges on wide-angle lenses)
  equidistant          cv2.fisheye.calibrate, 4 coefficients, started from the plumb_bob focal
                       length and principal point
Stereo: cv2.stereoCalibrate / cv2.fisheye.stereoCalibrate with fixed intrinsics. Points are
undistorted to convergence (100 iterations or 1e-12), never with OpenCV's default few steps.
"""
from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import ParamSpec, TypeVar

import cv2
import numpy as np

from stereocam.protocol.calibration import N_DIST

_Args = ParamSpec("_Args")
_Result = TypeVar("_Result")
SOLVE = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-12)
UNDISTORT = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-12)
MODELS = ("plumb_bob", "rational_polynomial", "equidistant")  # simplest first: ties go to the earlier
ALIASES = {"standard": "plumb_bob", "plumb_bob": "plumb_bob", "rational": "rational_polynomial",
           "rational_polynomial": "rational_polynomial", "fisheye": "equidistant", "equidistant": "equidistant"}


def _fisheye_flag(name: str) -> int:
    """cv2.fisheye.CALIB_* in OpenCV 4, the shared cv2.CALIB_* in OpenCV 5."""
    return getattr(cv2.fisheye, name, None) or getattr(cv2, name)


def _one_thread(solve: Callable[_Args, _Result]) -> Callable[_Args, _Result]:
    """Run an OpenCV solver on one thread: its parallel Jacobian sums change the last bits from run
    to run, and an ill-conditioned fit (a rational model on a few views) turns those bits into other
    outliers and other model scores. A factory tool gives the same answer for the same images."""
    @functools.wraps(solve)
    def run(*args: _Args.args, **kwargs: _Args.kwargs) -> _Result:
        threads = cv2.getNumThreads()
        cv2.setNumThreads(1)
        try:
            return solve(*args, **kwargs)
        finally:
            cv2.setNumThreads(threads)
    return run


class LensSolveError(ValueError):
    """OpenCV could not fit this lens model to the views."""


@dataclass
class MonoFit:
    """One camera's intrinsics and per-view reprojection RMS (px)."""

    rms: float
    K: np.ndarray
    D: np.ndarray
    per_view: np.ndarray


@dataclass
class StereoFit:
    """Extrinsics (left -> right) and the per-pair stereo reprojection RMS (left, right)."""

    rms: float
    R: np.ndarray
    T: np.ndarray
    per_view: np.ndarray


def _fisheye_pts(pts: list[np.ndarray], dim: int) -> list[np.ndarray]:
    return [np.asarray(p, np.float64).reshape(1, -1, dim) for p in pts]


@_one_thread
def calibrate_mono(model: str, obj: list[np.ndarray], img: list[np.ndarray], size: tuple[int, int],
                   start: MonoFit | None = None) -> MonoFit:
    """Fit one camera; `start` (a plumb_bob fit) seeds the rational and fisheye models."""
    try:
        if model == "equidistant":
            K0 = start.K.copy() if start is not None else None
            flags = _fisheye_flag("CALIB_RECOMPUTE_EXTRINSIC") | _fisheye_flag("CALIB_FIX_SKEW")
            if K0 is not None:
                flags |= _fisheye_flag("CALIB_USE_INTRINSIC_GUESS")
            o, i = _fisheye_pts(obj, 3), _fisheye_pts(img, 2)
            rms, K, D, rvecs, tvecs = cv2.fisheye.calibrate(o, i, size, K0, np.zeros(4), flags=flags, criteria=SOLVE)
            per_view = np.array([np.sqrt(np.mean(np.sum(
                (cv2.fisheye.projectPoints(oo, rv, tv, K, D)[0] - ii).reshape(-1, 2) ** 2, axis=1)))
                for oo, ii, rv, tv in zip(o, i, rvecs, tvecs)])
            return MonoFit(float(rms), K, D.ravel(), per_view)
        o = [np.asarray(p, np.float32).reshape(-1, 3) for p in obj]
        i = [np.asarray(p, np.float32).reshape(-1, 1, 2) for p in img]
        if model == "plumb_bob":
            rms, K, D, *_, err = cv2.calibrateCameraExtended(o, i, size, None, None, criteria=SOLVE)
        else:
            if start is None:
                start = calibrate_mono("plumb_bob", obj, img, size)
            D0 = np.zeros(8)
            D0[:5] = start.D[:5]
            flags = cv2.CALIB_RATIONAL_MODEL | cv2.CALIB_USE_INTRINSIC_GUESS
            rms, K, D, *_, err = cv2.calibrateCameraExtended(o, i, size, start.K.copy(), D0, flags=flags,
                                                             criteria=SOLVE)
    except cv2.error as exc:
        raise LensSolveError(f"{model}: {exc}") from exc
    D = D.ravel()[:N_DIST[model]]
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(D)) and np.isfinite(rms)):
        raise LensSolveError(f"{model}: the fit diverged")
    return MonoFit(float(rms), K, D, err.ravel())


@_one_thread
def calibrate_stereo(model: str, obj: list[np.ndarray], left: list[np.ndarray], right: list[np.ndarray],
                     size: tuple[int, int], fl: MonoFit, fr: MonoFit) -> StereoFit:
    """Extrinsics with both cameras' intrinsics fixed."""
    try:
        if model == "equidistant":
            o, l, r = _fisheye_pts(obj, 3), _fisheye_pts(left, 2), _fisheye_pts(right, 2)
            out = cv2.fisheye.stereoCalibrate(o, l, r, fl.K, fl.D, fr.K, fr.D, size, None, None,
                                              flags=_fisheye_flag("CALIB_FIX_INTRINSIC"), criteria=SOLVE)
            rms, R, T = out[0], out[5], out[6]
            per_view = _stereo_per_view(model, o, l, r, fl, fr, R, T)
        else:
            o = [np.asarray(p, np.float32).reshape(-1, 3) for p in obj]
            l = [np.asarray(p, np.float32).reshape(-1, 1, 2) for p in left]
            r = [np.asarray(p, np.float32).reshape(-1, 1, 2) for p in right]
            flags = cv2.CALIB_FIX_INTRINSIC | (cv2.CALIB_RATIONAL_MODEL if model == "rational_polynomial" else 0)
            rms, *_, R, T, _, _, _, _, per_view = cv2.stereoCalibrateExtended(
                o, l, r, fl.K, fl.D, fr.K, fr.D, size, None, None, flags=flags, criteria=SOLVE)
    except cv2.error as exc:
        raise LensSolveError(f"{model} stereo: {exc}") from exc
    return StereoFit(float(rms), np.asarray(R, np.float64), np.asarray(T, np.float64).ravel(), np.asarray(per_view))


def _stereo_per_view(model, o, l, r, fl, fr, R, T) -> np.ndarray:
    """Per pair (left, right) RMS with the left pose from the left view, the right through (R, T)."""
    out, T = [], np.asarray(T, np.float64).ravel()
    for oo, ll, rr in zip(o, l, r):
        rv, tv = solve_pose(model, oo.reshape(-1, 3), ll.reshape(-1, 2), fl.K, fl.D)
        Rl = cv2.Rodrigues(rv)[0]
        rv_r, tv_r = cv2.Rodrigues(R @ Rl)[0], R @ tv.ravel() + T
        el = project(model, oo.reshape(-1, 3), rv, tv, fl.K, fl.D) - ll.reshape(-1, 2)
        er = project(model, oo.reshape(-1, 3), rv_r, tv_r, fr.K, fr.D) - rr.reshape(-1, 2)
        out.append([np.sqrt(np.mean(np.sum(el ** 2, 1))), np.sqrt(np.mean(np.sum(er ** 2, 1)))])
    return np.array(out)


def undistort(model: str, pts: np.ndarray, K: np.ndarray, D: np.ndarray, R: np.ndarray | None = None,
              P: np.ndarray | None = None) -> np.ndarray:
    """Undistorted (optionally rotated and projected) points (N, 2), iterated to convergence."""
    p = np.asarray(pts, np.float64).reshape(-1, 1, 2)
    if model == "equidistant":
        return cv2.fisheye.undistortPoints(p, K, D, R=R, P=P, criteria=UNDISTORT).reshape(-1, 2)
    return cv2.undistortPoints(p, K, D, R=R, P=P, criteria=UNDISTORT).reshape(-1, 2)


def rectify_map(model: str, K: np.ndarray, D: np.ndarray, R: np.ndarray, P: np.ndarray,
                size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Float32 maps (H, W): rectified pixel -> raw pixel, through the lens (OpenCV's initUndistortRectifyMap)."""
    init = cv2.fisheye.initUndistortRectifyMap if model == "equidistant" else cv2.initUndistortRectifyMap
    return init(K, D, R, P, size, cv2.CV_32FC1)


def project(model: str, obj: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, K: np.ndarray,
            D: np.ndarray) -> np.ndarray:
    """Board points (N, 3) to pixels (N, 2) through a pose and the lens."""
    o = np.asarray(obj, np.float64).reshape(-1, 1, 3)
    if model == "equidistant":
        return cv2.fisheye.projectPoints(o, np.asarray(rvec, np.float64).reshape(3, 1),
                                         np.asarray(tvec, np.float64).reshape(3, 1), K, D)[0].reshape(-1, 2)
    return cv2.projectPoints(o, rvec, tvec, K, D)[0].reshape(-1, 2)


def solve_pose(model: str, obj: np.ndarray, img: np.ndarray, K: np.ndarray, D: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """Board pose from one view with the intrinsics fixed (on converged undistorted points)."""
    norm = undistort(model, img, K, D)
    ok, rvec, tvec = cv2.solvePnP(np.asarray(obj, np.float64).reshape(-1, 3), norm, np.eye(3), None,
                                  flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise LensSolveError("no board pose for a view")
    return rvec, tvec
