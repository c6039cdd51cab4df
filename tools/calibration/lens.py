"""Lens models for the calibration tool: one interface over OpenCV's pinhole and fisheye solvers.

  plumb_bob            cv2.calibrateCamera, 5 coefficients (k1, k2, p1, p2, k3)
  rational_polynomial  cv2.calibrateCamera with CALIB_RATIONAL_MODEL, 8 coefficients
  equidistant          cv2.fisheye.calibrate, 4 coefficients
Each model is fitted on its own terms, from several starts, and the start with the lowest RMS wins
(a start that fails or diverges is skipped; the model fails only when every start does):
  plumb_bob            OpenCV's own start (focal from the board homographies);
  rational_polynomial  the caller's fit (any model) as guess, OpenCV's cold start, and the
                       K of an equidistant fit of the same views (the start that holds on
                       strongly distorted wide-angle lenses, where a 5-coefficient fit fails);
                       with `fixed` (RATIONAL_REDUCED), the same starts with the
                       highest-order terms held at 0 (fit.py's fallback for a head whose full
                       fit folds the image beyond the views);
  equidistant          the caller's K, OpenCV's fisheye start (f = max(W, H) / pi, a ~180 degree
                       lens; given as a guess, fisheye_start) and the focal length of the board
                       homographies (narrow lenses).
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
from stereocam.protocol.rectification import CONVERGED_STEPS, viewing_rays

_Args = ParamSpec("_Args")
_Result = TypeVar("_Result")
SOLVE = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-12)
UNDISTORT = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-12)
MODELS = ("plumb_bob", "equidistant", "rational_polynomial")  # simplest first (8 coefficients last): ties go to the earlier
ALIASES = {"standard": "plumb_bob", "plumb_bob": "plumb_bob", "rational": "rational_polynomial",
           "rational_polynomial": "rational_polynomial", "fisheye": "equidistant", "equidistant": "equidistant"}


# rational_polynomial with its highest-order terms held at 0, in the order fit.fit_head tries them
# when the full fit's rectification folds: a fit free to bend anywhere can match every corner of
# views that stop short of the image's corners and still turn back beyond them (a 110 degree lens
# seen to 0.9 of its half-width); fewer terms extrapolate more tamely. The calibration stays a
# rational_polynomial one (those coefficients 0), stored and exported as such.
RATIONAL_REDUCED = (cv2.CALIB_FIX_K3 | cv2.CALIB_FIX_K6,
                    cv2.CALIB_FIX_K3 | cv2.CALIB_FIX_K5 | cv2.CALIB_FIX_K6)


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


def _per_view_fisheye(o: list[np.ndarray], i: list[np.ndarray], rvecs, tvecs, K: np.ndarray, D: np.ndarray
                      ) -> np.ndarray:
    return np.array([np.sqrt(np.mean(np.sum(
        (cv2.fisheye.projectPoints(oo, rv, tv, K, D)[0] - ii).reshape(-1, 2) ** 2, axis=1)))
        for oo, ii, rv, tv in zip(o, i, rvecs, tvecs)])


def homography_K(obj: list[np.ndarray], img: list[np.ndarray], size: tuple[int, int]) -> np.ndarray:
    """Pinhole K from the board homographies (cv2.initCameraMatrix2D), the image centre as principal point."""
    o = [np.asarray(p, np.float32).reshape(-1, 3) for p in obj]
    i = [np.asarray(p, np.float32).reshape(-1, 1, 2) for p in img]
    K = cv2.initCameraMatrix2D(o, i, size)
    if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise LensSolveError("no focal length from the board homographies")
    return K


def _fisheye_once(obj: list[np.ndarray], img: list[np.ndarray], size: tuple[int, int], K0: np.ndarray | None,
                  D0: np.ndarray | None = None) -> MonoFit:
    flags = _fisheye_flag("CALIB_RECOMPUTE_EXTRINSIC") | _fisheye_flag("CALIB_FIX_SKEW")
    if K0 is not None:
        flags |= _fisheye_flag("CALIB_USE_INTRINSIC_GUESS")
        K0 = np.array(K0, np.float64)
    o, i = _fisheye_pts(obj, 3), _fisheye_pts(img, 2)
    d0 = np.zeros(4) if D0 is None else np.array(D0, np.float64).reshape(4)
    rms, K, D, rvecs, tvecs = cv2.fisheye.calibrate(o, i, size, K0, d0, flags=flags, criteria=SOLVE)
    return MonoFit(float(rms), K, D.ravel(), _per_view_fisheye(o, i, rvecs, tvecs, K, D))


def fisheye_start(size: tuple[int, int]) -> np.ndarray:
    """OpenCV's fisheye start, f = max(W, H) / pi (a ~180 degree lens) at the image centre, as an
    explicit guess: left to OpenCV (no CALIB_USE_INTRINSIC_GUESS) the same start failed one solve in
    three on random subsets of a 180 degree unit's 640x480 views (InitExtrinsics asserts when an
    iteration steps the lens to where a view's corners have no pinhole image); given, none of 30."""
    w, h = size
    f = max(w, h) / np.pi
    return np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])


def _pinhole_once(model: str, obj: list[np.ndarray], img: list[np.ndarray], size: tuple[int, int],
                  K0: np.ndarray | None, D0: np.ndarray | None, fixed: int = 0) -> MonoFit:
    o = [np.asarray(p, np.float32).reshape(-1, 3) for p in obj]
    i = [np.asarray(p, np.float32).reshape(-1, 1, 2) for p in img]
    flags = (cv2.CALIB_RATIONAL_MODEL | fixed) if model == "rational_polynomial" else 0
    if K0 is not None:
        flags |= cv2.CALIB_USE_INTRINSIC_GUESS
        d = np.zeros(8)
        if D0 is not None:
            d[:min(5, len(D0))] = np.asarray(D0).ravel()[:5]
        K0, D0 = np.array(K0, np.float64), d
    rms, K, D, *_, err = cv2.calibrateCameraExtended(o, i, size, K0, D0, flags=flags, criteria=SOLVE)
    return MonoFit(float(rms), K, D.ravel()[:N_DIST[model]], err.ravel())


def _plausible(fit: MonoFit, size: tuple[int, int]) -> bool:
    """Finite, positive focal lengths, principal point within the image grown by half on each side."""
    K, (w, h) = fit.K, size
    return bool(np.all(np.isfinite(fit.K)) and np.all(np.isfinite(fit.D)) and np.isfinite(fit.rms)
                and K[0, 0] > 0 and K[1, 1] > 0 and -w / 2 < K[0, 2] < 1.5 * w and -h / 2 < K[1, 2] < 1.5 * h)


def folds(model: str, fit: MonoFit, size: tuple[int, int]) -> bool:
    """Whether the radial distortion turns back before it reaches the farthest image corner: the
    distorted radius (or fisheye angle) must grow with the undistorted one over the whole image."""
    K, D, (w, h) = fit.K, np.asarray(fit.D, np.float64), size
    corners = np.array([[0, 0], [w, 0], [0, h], [w, h]], np.float64)
    reach = float(np.max(np.hypot((corners[:, 0] - K[0, 2]) / K[0, 0], (corners[:, 1] - K[1, 2]) / K[1, 1])))
    if model == "equidistant":
        t = np.linspace(0.0, np.pi, 4000)
        rd = t * (1 + D[0] * t ** 2 + D[1] * t ** 4 + D[2] * t ** 6 + D[3] * t ** 8)
    else:
        r = np.linspace(0.0, 50.0 * max(reach, 1.0), 20000)
        k = np.zeros(8)
        k[:len(D)] = D
        r2 = r * r
        rd = r * (1 + k[0] * r2 + k[1] * r2 ** 2 + k[4] * r2 ** 3) / (1 + k[5] * r2 + k[6] * r2 ** 2 + k[7] * r2 ** 3)
    rising = np.diff(rd) > 0
    turn = int(np.argmin(rising)) if not rising.all() else len(rising)
    return bool(np.max(rd[:turn + 1]) < reach)


def border_rays_finite(model: str, fit: MonoFit, size: tuple[int, int]) -> bool:
    """Whether every border pixel (9 per side) undistorts to a finite viewing ray as the
    rectification computes it (SPEC §12.6 step 2). A rational fit can put a pole of its distortion
    inside the image, beyond the corners the views reached: that head has no rectification."""
    w, h = size
    t = np.linspace(0.0, 1.0, 9)
    pts = np.concatenate([np.column_stack([t * (w - 1), np.zeros(9)]), np.column_stack([t * (w - 1), np.full(9, h - 1.0)]),
                          np.column_stack([np.zeros(9), t * (h - 1)]), np.column_stack([np.full(9, w - 1.0), t * (h - 1)])])
    with np.errstate(all="ignore"):
        rays = viewing_rays(fit.K, fit.D, pts, CONVERGED_STEPS, model)
    return bool(np.all(np.isfinite(rays)))


@_one_thread
def calibrate_mono(model: str, obj: list[np.ndarray], img: list[np.ndarray], size: tuple[int, int],
                   start: MonoFit | None = None, fixed: int = 0) -> MonoFit:
    """Fit one camera from the starts of the module docstring; `start` (a fit of any model) is one of
    them; `fixed`: rational_polynomial's terms held at 0 (one of RATIONAL_REDUCED, or 0: none)."""
    starts: list[Callable[[], MonoFit]] = []
    if fixed and model != "rational_polynomial":
        raise LensSolveError(f"{model}: no terms to hold at 0 (only rational_polynomial has them)")
    if model == "plumb_bob":
        starts.append(lambda: _pinhole_once(model, obj, img, size, None, None))
    elif model == "rational_polynomial":
        if start is not None:
            # a fisheye start's D means nothing here; a reduced fit's D from a full one would be
            # the held terms' too: its K only
            d0 = start.D if len(start.D) >= 5 and not fixed else None
            starts.append(lambda: _pinhole_once(model, obj, img, size, start.K, d0, fixed))
        starts.append(lambda: _pinhole_once(model, obj, img, size, None, None, fixed))
        starts.append(lambda: _pinhole_once(model, obj, img, size, calibrate_mono("equidistant", obj, img, size).K,
                                            None, fixed))
    elif model == "equidistant":
        if start is not None:
            starts.append(lambda: _fisheye_once(obj, img, size, start.K))
        starts.append(lambda: _fisheye_once(obj, img, size, fisheye_start(size)))
        starts.append(lambda: _fisheye_once(obj, img, size, homography_K(obj, img, size)))
    else:
        raise LensSolveError(f"unknown lens model {model!r}")
    best: tuple[tuple[bool, float], MonoFit] | None = None
    failures: list[str] = []
    for attempt in starts:
        try:
            fit = attempt()
        except (cv2.error, LensSolveError) as exc:
            failures.append(str(exc).strip().splitlines()[-1])
            continue
        if not _plausible(fit, size):
            failures.append("the fit diverged")
            continue
        # a start whose lens folds the image, or has no ray for some border pixel, loses to any other
        rank = (folds(model, fit, size) or not border_rays_finite(model, fit, size), fit.rms)
        if best is None or rank < best[0]:
            best = (rank, fit)
    if best is None:
        raise LensSolveError(f"{model}: every start failed ({'; '.join(dict.fromkeys(failures))})")
    return best[1]


@_one_thread
def calibrate_stereo(model: str, obj: list[np.ndarray], left: list[np.ndarray], right: list[np.ndarray],
                     size: tuple[int, int], fl: MonoFit, fr: MonoFit) -> StereoFit:
    """Extrinsics with both cameras' intrinsics fixed."""
    try:
        if model == "equidistant":
            o, l, r = _fisheye_pts(obj, 3), _fisheye_pts(left, 2), _fisheye_pts(right, 2)
            out = cv2.fisheye.stereoCalibrate(o, l, r, fl.K, fl.D, fr.K, fr.D, size, None, None,
                                              flags=_fisheye_flag("CALIB_FIX_INTRINSIC"), criteria=SOLVE)
            R, T = refine_stereo(model, obj, left, right, fl, fr, out[5], out[6])
            per_view = _stereo_per_view(model, o, l, r, fl, fr, R, T)
            rms = float(np.sqrt(np.mean(per_view ** 2)))
        else:
            o = [np.asarray(p, np.float32).reshape(-1, 3) for p in obj]
            l = [np.asarray(p, np.float32).reshape(-1, 1, 2) for p in left]
            r = [np.asarray(p, np.float32).reshape(-1, 1, 2) for p in right]
            flags = cv2.CALIB_FIX_INTRINSIC | (cv2.CALIB_RATIONAL_MODEL if model == "rational_polynomial" else 0)
            rms, *_, R, T, _, _, _, _, per_view = cv2.stereoCalibrateExtended(
                o, l, r, fl.K, fl.D, fr.K, fr.D, size, None, None, flags=flags, criteria=SOLVE)
    except cv2.error:  # OpenCV's own solve failed: the relative pose from the views' poses
        return _stereo_from_poses(model, obj, left, right, fl, fr)
    return StereoFit(float(rms), np.asarray(R, np.float64), np.asarray(T, np.float64).ravel(), np.asarray(per_view))


def _stereo_from_poses(model: str, obj: list[np.ndarray], left: list[np.ndarray], right: list[np.ndarray],
                       fl: MonoFit, fr: MonoFit) -> StereoFit:
    """Left -> right transform started from the mean (chordal for R, median for T) of the per-pair
    ones, refined (refine_stereo). OpenCV 5's cv2.fisheye.stereoCalibrate needs this for views with
    different corner counts (ChArUco, AprilGrid): it fails on them."""
    Rs, Ts = [], []
    for o, l, r in zip(obj, left, right):
        rl, tl = solve_pose(model, o, l, fl.K, fl.D)
        rr, tr = solve_pose(model, o, r, fr.K, fr.D)
        Ri = cv2.Rodrigues(rr)[0] @ cv2.Rodrigues(rl)[0].T
        Rs.append(Ri)
        Ts.append(tr.ravel() - Ri @ tl.ravel())
    u, _, vt = np.linalg.svd(np.sum(Rs, axis=0))
    R = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    R, T = refine_stereo(model, obj, left, right, fl, fr, R, np.median(np.array(Ts), axis=0))
    per_view = _stereo_per_view(model, *(_fisheye_pts(x, d) for x, d in ((obj, 3), (left, 2), (right, 2))),
                                fl, fr, R, T)
    if not np.all(np.isfinite(per_view)):
        raise LensSolveError(f"{model} stereo: no relative pose")
    return StereoFit(float(np.sqrt(np.mean(per_view ** 2))), R, T, per_view)


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
    """Board pose from one view with the intrinsics fixed: solvePnP on converged undistorted points,
    then refined on the pixel reprojection error through the lens (Levenberg-Marquardt), so a wide
    lens's far-off-axis corners are not overweighted."""
    o = np.asarray(obj, np.float64).reshape(-1, 3)
    pts = np.asarray(img, np.float64).reshape(-1, 2)
    ok, rvec, tvec = cv2.solvePnP(o, undistort(model, pts, K, D), np.eye(3), None, flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise LensSolveError("no board pose for a view")
    if model != "equidistant":
        return cv2.solvePnPRefineLM(o, pts, K, D, rvec, tvec, SOLVE)
    return _refine_pose(model, o, pts, K, D, rvec, tvec)


def _refine_pose(model: str, obj: np.ndarray, img: np.ndarray, K: np.ndarray, D: np.ndarray, rvec: np.ndarray,
                 tvec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rvec, tvec) minimising the pixel error of project()."""
    x = _levenberg_marquardt(np.concatenate([np.ravel(rvec), np.ravel(tvec)]),
                             lambda p: (project(model, obj, p[:3], p[3:], K, D) - img).ravel())
    return x[:3].reshape(3, 1), x[3:].reshape(3, 1)


def _levenberg_marquardt(x0: np.ndarray, residual: Callable[[np.ndarray], np.ndarray], steps: int = 20
                         ) -> np.ndarray:
    """A few-parameter least-squares solve (forward-difference Jacobian)."""
    x = np.asarray(x0, np.float64).copy()
    r = residual(x)
    cost, damping = float(r @ r), 1e-3
    for _ in range(steps):
        J = np.empty((r.size, x.size))
        for k in range(x.size):
            h = 1e-7 * max(1.0, abs(x[k]))
            moved = x.copy()
            moved[k] += h
            J[:, k] = (residual(moved) - r) / h
        A = J.T @ J
        step = np.linalg.solve(A + damping * np.diag(np.diag(A) + 1e-12), -(J.T @ r))
        r_new = residual(x + step)
        if float(r_new @ r_new) < cost:
            x, r, cost, damping = x + step, r_new, float(r_new @ r_new), damping * 0.3
            if np.linalg.norm(step) < 1e-12:
                break
        else:
            damping *= 10
    return x


def refine_stereo(model: str, obj: list[np.ndarray], left: list[np.ndarray], right: list[np.ndarray],
                  fl: MonoFit, fr: MonoFit, R: np.ndarray, T: np.ndarray, rounds: int = 4
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(R, T) minimising both views' pixel errors with one board pose per pair, intrinsics fixed
    (cv2.fisheye.stereoCalibrate stops short of it): alternately each pair's pose, then (R, T)."""
    o = [np.asarray(p, np.float64).reshape(-1, 3) for p in obj]
    l = [np.asarray(p, np.float64).reshape(-1, 2) for p in left]
    r = [np.asarray(p, np.float64).reshape(-1, 2) for p in right]
    rt = np.concatenate([cv2.Rodrigues(np.asarray(R, np.float64))[0].ravel(), np.ravel(T)])
    poses = [np.concatenate([np.ravel(v) for v in solve_pose(model, oo, ll, fl.K, fl.D)]) for oo, ll in zip(o, l)]

    def right_error(pose: np.ndarray, ext: np.ndarray, oo: np.ndarray, rr: np.ndarray) -> np.ndarray:
        Rr = cv2.Rodrigues(ext[:3])[0] @ cv2.Rodrigues(pose[:3])[0]
        tr = cv2.Rodrigues(ext[:3])[0] @ pose[3:] + ext[3:]
        return (project(model, oo, cv2.Rodrigues(Rr)[0], tr, fr.K, fr.D) - rr).ravel()

    def pair_error(pose: np.ndarray, ext: np.ndarray, oo: np.ndarray, ll: np.ndarray, rr: np.ndarray) -> np.ndarray:
        return np.concatenate([(project(model, oo, pose[:3], pose[3:], fl.K, fl.D) - ll).ravel(),
                               right_error(pose, ext, oo, rr)])

    def head_error(ext: np.ndarray, poses: list[np.ndarray]) -> np.ndarray:
        return np.concatenate([right_error(p, ext, oo, rr) for p, oo, rr in zip(poses, o, r)])

    for _ in range(rounds):
        poses = [_levenberg_marquardt(pose, functools.partial(pair_error, ext=rt, oo=oo, ll=ll, rr=rr), steps=8)
                 for pose, oo, ll, rr in zip(poses, o, l, r)]
        rt = _levenberg_marquardt(rt, functools.partial(head_error, poses=poses), steps=8)
    return cv2.Rodrigues(rt[:3])[0], rt[3:]
