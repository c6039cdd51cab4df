"""Fitting a stereo head to matched board points: outlier removal, lens-model choice, metrics, gate.

Per-pair residuals (px) of a fit, the quantities outliers are judged by:
  reproj_left / reproj_right   RMS reprojection error of that view in its camera's own solve;
  stereo                       the larger of the pair's two RMS errors in the stereo solve (one board
                               pose per pair, the right camera through R, T);
  epipolar                     RMS over the pair's corners of fy_left · (atan(y_l/z_l) − atan(y_r/z_r)),
                               (x, y, z) the corner's ray undistorted to convergence and rotated by
                               the rectification (protocol/rectification.py): y_left_rect − y_right_rect
                               near the centre (at the raw focal length), the epipolar planes' angle
                               in raw px anywhere.
A pair is an outlier when one of them exceeds max(median + k·1.4826·MAD, ratio·median, floor_px) over
the pairs still in (k = outlier_k, ratio = outlier_ratio; an error within floor_px is never an outlier,
however clean the others); the fit is redone without them, up to
outlier_rounds times, never dropping more than max_drop_fraction of the pairs (the worst go first).
A left and right frame not taken at the same instant shows as a stereo/epipolar outlier.

Lens model: each candidate is fitted on the training pairs (all but every holdout_every-th) and
scored on the held-out pairs by sqrt(mean(reproj_left², reproj_right², epipolar²)), reprojection
with the board pose of each held-out view solved with the intrinsics fixed. The simplest model whose
score is within model_tie (relative) of the best one wins. The final head is fitted on every pair
kept; its held-out epipolar RMS is the chosen model's on the held-out pairs.
"""
from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.errors import ConfigError
from stereocam.protocol.calibration_limits import check_rectifiable
from stereocam.protocol.rectification import RectifiedGeometry, stereo_rectify
from stereocam.tools.calibration.lens import (
    RATIONAL_REDUCED, LensSolveError, MonoFit, StereoFit, calibrate_mono, calibrate_stereo, project, rectify_map, solve_pose,
    undistort,
)

METRICS = ("reproj_left", "reproj_right", "stereo", "epipolar")
CROSS_START_RATIO = 2.0  # fit_head: a camera's RMS this many times the other's is fitted again from the other's


class UnrectifiableFitError(LensSolveError):
    """A head that was fitted (its stereo RMS known) but whose calibration has no usable
    rectification (SPEC §12.4 step 4): a fit of mismatched pairs, or a lens model that does not
    hold at the image's border."""

    def __init__(self, model: str, reason: str, stereo_rms: float) -> None:
        super().__init__(f"{model}: {reason}")
        self.model, self.reason, self.stereo_rms = model, reason, stereo_rms


class NoFitError(LensSolveError):
    """No lens model gave a usable fit; `unrectifiable` holds those that fitted but do not rectify."""

    def __init__(self, message: str, causes: Sequence[LensSolveError]) -> None:
        super().__init__(message)
        self.unrectifiable = [c for c in causes if isinstance(c, UnrectifiableFitError)]


@dataclass
class PairPoints:
    """One usable pair: object points (N, 3), left and right image points (N, 2), its index."""

    index: int
    label: str
    obj: np.ndarray
    left: np.ndarray
    right: np.ndarray


@dataclass
class HeadFit:
    """A fitted stereo head and its rectification."""

    left: MonoFit
    right: MonoFit
    stereo: StereoFit
    calibration: StereoCalibration
    geometry: RectifiedGeometry

    @property
    def model(self) -> str:
        return self.calibration.lens_model


@dataclass(frozen=True)
class OutlierRules:
    """Thresholds of the outlier rule (see the module docstring)."""

    k: float = 5.0
    ratio: float = 2.5
    rounds: int = 3
    max_drop_fraction: float = 0.3
    floor_px: float = 0.1

    def __post_init__(self) -> None:
        """Raises ConfigError for a rule that cannot be applied (NaN, negative, a fraction outside 0..1)."""
        for name in ("k", "ratio", "floor_px"):
            check_finite(getattr(self, name), f"outlier {name}", 0.0)
        check_finite(self.max_drop_fraction, "outlier max_drop_fraction", 0.0, 1.0)
        if isinstance(self.rounds, bool) or not isinstance(self.rounds, numbers.Integral) or self.rounds < 0:
            raise ConfigError(f"outlier rounds must be a whole number >= 0, got {self.rounds!r}")


def check_finite(value: float, what: str, low: float, high: float = math.inf) -> float:
    """``value`` if it is a finite number within [low, high]; else ConfigError naming ``what``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not (
            math.isfinite(value) and low <= value <= high):
        bounds = f">= {low:g}" if high == math.inf else f"within {low:g}..{high:g}"
        raise ConfigError(f"{what} must be a finite number {bounds}, got {value!r}")
    return float(value)


def fit_head(model: str, pairs: Sequence[PairPoints], size: tuple[int, int], start: HeadFit | None = None,
             storable: bool = True, reduce: bool = True) -> HeadFit:
    """Per-camera solves, then stereo with fixed intrinsics. Raises LensSolveError; with `storable`,
    UnrectifiableFitError for a head a camera would not store. Without it (a fit whose residuals only
    judge outliers) the head need only have the rectified rotations the epipolar error is measured in:
    one gross outlier can spoil a fit's rectification, and the fit must still show which pair it is.
    A rational_polynomial head whose rectification folds is fitted again with its highest-order terms
    held at 0 (lens.RATIONAL_REDUCED, in turn; not with `reduce` False); the first that a camera
    would store is the fit."""
    try:
        return _fit_head(model, pairs, size, start, storable, 0)
    except UnrectifiableFitError as exc:
        if model != "rational_polynomial" or not reduce:
            raise
        first = exc
    for fixed in RATIONAL_REDUCED:
        try:
            return _fit_head(model, pairs, size, start, storable, fixed)
        except UnrectifiableFitError:
            continue
    raise first


def _fit_head(model: str, pairs: Sequence[PairPoints], size: tuple[int, int], start: HeadFit | None,
              storable: bool, fixed: int) -> HeadFit:
    obj = [p.obj for p in pairs]
    left, right = [p.left for p in pairs], [p.right for p in pairs]
    fl = calibrate_mono(model, obj, left, size, start.left if start else None, fixed)
    fr = calibrate_mono(model, obj, right, size, start.right if start else None, fixed)
    # the cameras of a head have lenses of one class: a camera whose fit is far worse than the
    # other's (a false minimum: a wide lens's rational fit where no start of its own held) is fitted
    # again from the other's fit
    if fl.rms > CROSS_START_RATIO * fr.rms:
        fl = calibrate_mono(model, obj, left, size, fr, fixed)
    elif fr.rms > CROSS_START_RATIO * fl.rms:
        fr = calibrate_mono(model, obj, right, size, fl, fixed)
    st = calibrate_stereo(model, obj, [p.left for p in pairs], [p.right for p in pairs], size, fl, fr)
    try:
        calib = StereoCalibration(size, fl.K, fl.D, fr.K, fr.D, st.R, st.T, model)
        # the rule a camera applies before it stores a calibration (SPEC §12.4 step 4): a usable
        # rectification, and no folding — a fit can match every corner and still fold where none was seen
        if storable:
            check_rectifiable(calib, rectify_map)
        with np.errstate(all="ignore"):
            geometry = stereo_rectify(calib)
    except ValueError as exc:  # CalibrationImplausible is one
        raise UnrectifiableFitError(model, str(exc), st.rms) from exc
    return HeadFit(fl, fr, st, calib, geometry)


def epipolar_dy(fit: HeadFit, left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Epipolar error per corner (px of the raw image): the angle between the corner's epipolar
    planes seen from the left and from the right (atan of the rectified y/z) times the left camera's
    focal length fy. Near the image centre it is y_left_rect − y_right_rect at the raw image's scale;
    it stays a fair measure far off axis (a wide or fisheye lens), where rectified pinhole
    coordinates, and the rectification's zoom, grow without bound."""
    c, g = fit.calibration, fit.geometry
    yl = undistort(c.lens_model, left, c.K_left, c.D_left, g.R1)[:, 1]
    yr = undistort(c.lens_model, right, c.K_right, c.D_right, g.R2)[:, 1]
    return c.K_left[1, 1] * (np.arctan(yl) - np.arctan(yr))


def rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def in_sample_errors(fit: HeadFit, pairs: Sequence[PairPoints]) -> dict[str, np.ndarray]:
    """The per-pair residuals of the module docstring for the pairs `fit` was solved on."""
    return {"reproj_left": fit.left.per_view, "reproj_right": fit.right.per_view,
            "stereo": fit.stereo.per_view.max(axis=1),
            "epipolar": np.array([rms(epipolar_dy(fit, p.left, p.right)) for p in pairs])}


def _held_reproj(fit: HeadFit, obj: np.ndarray, pts: np.ndarray, mono: MonoFit) -> float:
    rvec, tvec = solve_pose(fit.model, obj, pts, mono.K, mono.D)
    return rms(np.linalg.norm(project(fit.model, obj, rvec, tvec, mono.K, mono.D) - pts, axis=1))


def held_out_errors(fit: HeadFit, pairs: Sequence[PairPoints]) -> dict[str, np.ndarray]:
    """Per held-out pair: reprojection RMS per camera (pose solved, intrinsics fixed) and epipolar RMS."""
    return {"reproj_left": np.array([_held_reproj(fit, p.obj, p.left, fit.left) for p in pairs]),
            "reproj_right": np.array([_held_reproj(fit, p.obj, p.right, fit.right) for p in pairs]),
            "epipolar": np.array([rms(epipolar_dy(fit, p.left, p.right)) for p in pairs])}


def score(errors: dict[str, np.ndarray]) -> float:
    """Model-choice score of held-out errors (px)."""
    return float(np.sqrt(np.mean([np.mean(errors[k] ** 2) for k in ("reproj_left", "reproj_right", "epipolar")])))


def _limits(values: np.ndarray, rules: OutlierRules) -> float:
    med = float(np.median(values))
    mad = float(np.median(np.abs(values - med)))
    return max(med + rules.k * 1.4826 * mad, rules.ratio * med, rules.floor_px)


def robust_fit(model: str, pairs: list[PairPoints], size: tuple[int, int], rules: OutlierRules,
               start_model: str | None = None) -> tuple[HeadFit, list[PairPoints], dict[int, str]]:
    """Fit, drop outlier pairs, refit; returns (fit, pairs kept, {index: reason} of those dropped).
    The fits judge outliers only: they need not rectify (fit_head's `storable`)."""
    kept, dropped = list(pairs), {}
    budget = int(rules.max_drop_fraction * len(pairs))
    for round_ in range(rules.rounds + 1):
        fit = fit_head(model, kept, size, try_fit(start_model, kept, size) if start_model else None, storable=False)
        if round_ == rules.rounds or budget == 0:
            break
        errors = in_sample_errors(fit, kept)
        worst: dict[int, tuple[float, str]] = {}
        for name in METRICS:
            limit = _limits(errors[name], rules)
            for i in np.flatnonzero(errors[name] > limit).tolist():
                severity = errors[name][i] / limit
                if severity > worst.get(i, (0.0, ""))[0]:
                    worst[i] = (severity, f"{name.replace('_', ' ')} {errors[name][i]:.3f} px > {limit:.3f} px "
                                          f"(median {np.median(errors[name]):.3f} px)")
        if not worst:
            break
        chosen = sorted(worst, key=lambda i: -worst[i][0])[:budget]
        budget -= len(chosen)
        for i in chosen:
            dropped[kept[i].index] = worst[i][1]
        kept = [p for i, p in enumerate(kept) if i not in set(chosen)]
    return fit, kept, dropped


def try_fit(model: str, pairs: Sequence[PairPoints], size: tuple[int, int]) -> HeadFit | None:
    """fit_head, or None where the model does not fit (a start for another model, never required,
    so it need not rectify)."""
    try:
        return fit_head(model, pairs, size, storable=False)
    except LensSolveError:
        return None


@dataclass
class ModelChoice:
    """The lens model chosen, the held-out score of each model that fitted, why the others failed."""

    model: str
    scores: dict[str, float]
    failures: dict[str, str]
    held_errors: dict[str, np.ndarray]
    fit: HeadFit


def choose_model(models: Sequence[str], train: list[PairPoints], held: list[PairPoints],
                 size: tuple[int, int], tie: float) -> ModelChoice:
    """Fit each model on `train` on its own terms (a plumb_bob fit, where there is one, is one more
    start for the others, also where plumb_bob is not among `models`) and score it on `held`; a model that fails is listed, never fatal while
    another one fits. Raises NoFitError when none fits, ConfigError for a `tie` that is not a finite
    number >= 0."""
    check_finite(tie, "model tie", 0.0)
    scores: dict[str, float] = {}
    errors: dict[str, dict[str, np.ndarray]] = {}
    fits: dict[str, HeadFit] = {}
    failures: dict[str, str] = {}
    causes: list[LensSolveError] = []
    starter = None if "plumb_bob" in models else try_fit("plumb_bob", train, size)
    for model in models:
        try:
            fits[model] = fit_head(model, train, size, fits.get("plumb_bob", starter))
            errors[model] = held_out_errors(fits[model], held)
            scores[model] = score(errors[model])
        except LensSolveError as exc:
            fits.pop(model, None)
            failures[model] = str(exc)
            causes.append(exc)
    if not scores:
        raise NoFitError("no lens model could be fitted: " + "; ".join(failures.values()), causes)
    best = min(scores.values())
    chosen = next(m for m in models if m in scores and scores[m] <= best * (1 + tie))
    return ModelChoice(chosen, scores, failures, errors[chosen], fits[chosen])
