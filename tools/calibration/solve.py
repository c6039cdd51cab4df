"""Factory stereo calibration engine: detect, collect pairs, drop outliers, choose the lens model,
solve, measure, gate.

calibrate_pairs() consumes an iterator of raw (left, right) u8 image pairs — files in offline mode,
the device's raw stream in device mode — and returns a CalibrationResult.

  1. Detect (tools/calibration/boards.py): chessboards with both OpenCV detectors, corner order made
     consistent between left and right; ChArUco boards with partial views (common ids).
  2. Collect. Offline (select=False): every pair with the board in both images. Live capture
     (select=True, ROS camera_calibration style): the left view gives p = (X, Y, size, skew) in
     [0,1]^4 (X, Y = mean corner position, the image shrunk by half the board's apparent size;
     size = sqrt(board quad area / image area); skew = min(1, 2·|π/2 − angle at the top-right
     corner|)); a view is kept only if its L1 distance to every kept view is > min_distance,
     every holdout_every-th pair with the board is kept regardless; coverage per parameter =
     min(1, (max − min) / range), ranges (0.7, 0.7, 0.4, 0.5). It stops reading once max_views
     views and min_holdout held-out pairs are in, so an endless stream is fine.
  3. Outliers, lens model, final fit: tools/calibration/fit.py (residual-based outlier removal, model
     chosen on held-out pairs — every holdout_every-th pair kept — final fit on every pair kept).
     A fit whose lens model folds the image, or whose rectified views miss the sensors, counts as
     no fit (the rule a camera applies before storing, SPEC §12.4): the next model is chosen. The
     outlier screening's fits are exempt (they only judge residuals: one gross outlier can spoil a
     fit's rectification, and that fit must still show which pair it is).
  4. Metrics (px of the raw image, N = number of corners):
       rms_left / rms_right = sqrt( Σ_views Σ_corners |x_obs − x_proj|² / N ) of that camera's own
         solve on every pair kept; rms_stereo = the stereo solve's RMS over both cameras;
       epipolar_rms_px = sqrt( Σ_held-out Σ_corners dy² / N ), dy the epipolar error of calib_fit.epipolar_dy
         (y_left_rect − y_right_rect at the raw focal length near the centre), of the chosen
         model fitted without the held-out pairs; epipolar_all_rms_px the same over every pair kept,
         with the final fit.
  5. Gate (CalibrationResult.failures lists every failed rule; passed = none failed; where heads were
     fitted but none rectifies, GateFailedError lists their failures instead): rms_stereo ≤
     max_stereo_rms_px; epipolar_rms_px ≤ max_epipolar_rms_px; plausibility: principal points
     inside the image, fy/fx within [1/max_pixel_aspect, max_pixel_aspect], baseline within
     [min_baseline_m, max_baseline_m].
  6. Synchronisation (tools/calibration/sync.py): every pair with the board, kept or dropped, is checked
     for a left and right frame not taken at the same instant; the result says which and by how much.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from stereocam.protocol.rectification import RectifiedGeometry
from stereocam.tools.calibration.boards import (
    REFINED, Board, Detection, describe, detect_all, gray, match_pair, too_small,
)
from stereocam.tools.calibration.coverage import CoverageSelector, view_params
from stereocam.tools.calibration.fit import (
    CROSS_START_RATIO, HeadFit, ModelChoice, NoFitError, OutlierRules, PairPoints, UnrectifiableFitError, check_finite,
    choose_model, epipolar_dy, fit_head, held_out_errors, rms, robust_fit,
)
from stereocam.tools.calibration.lens import MODELS, LensSolveError, calibrate_mono
from stereocam.tools.calibration.sync import SyncReport, check_sync
from stereocam.protocol.calibration import CalibrationQuality, StereoCalibration
from stereocam.protocol.errors import ConfigError, StereoCamError

ViewStatus = Literal["used", "dropped", "redundant", "no_board"]


class CalibrationError(StereoCamError):
    """Calibration could not produce a solution at all."""


class BoardNotFoundError(CalibrationError):
    """No pair showed the board in both images."""


class UnusableImagesError(CalibrationError, ValueError):
    """No pair of the set could be used at all: every image unreadable, or no two of one size."""


class TooFewViewsError(CalibrationError):
    """Not enough distinct views (or held-out views) to solve and measure."""


class GateFailedError(CalibrationError):
    """Heads were fitted but none can be stored: `failures` lists the gate's rules they break (their
    stereo RMS, their rectification), as CalibrationResult.failures does for a fit that rectifies."""

    def __init__(self, failures: list[str], pairs: int) -> None:
        super().__init__(f"no fit of the {pairs} pairs can be stored: " + "; ".join(failures))
        self.failures = failures


@dataclass(frozen=True)
class SolveConfig:
    """Tunables of calibrate_pairs (see the module docstring and tools/calibration/fit.py)."""

    max_stereo_rms_px: float = 1.0
    max_epipolar_rms_px: float = 0.8
    min_views: int = 8            # live: distinct views needed
    max_views: int = 40           # live: stop after this many kept views
    min_pairs: int = 5            # offline: pairs with the board needed (after outliers)
    holdout_every: int = 5
    min_holdout: int = 1
    min_distance: float = 0.2
    lens_model: str = "auto"
    model_tie: float = 0.05
    outliers: OutlierRules = OutlierRules()
    max_pixel_aspect: float = 1.5
    min_baseline_m: float = 1e-4
    max_baseline_m: float = 100.0

    def __post_init__(self) -> None:
        """Raises ConfigError for a NaN gate threshold (it would pass every head), a model_tie that
        is not a finite number >= 0, or max_views under 1."""
        for name in ("max_stereo_rms_px", "max_epipolar_rms_px", "max_pixel_aspect", "min_baseline_m",
                     "max_baseline_m"):
            if math.isnan(getattr(self, name)):
                raise ConfigError(f"gate {name} must be a number, got NaN")
        check_finite(self.model_tie, "model_tie", 0.0)
        if self.max_views < 1:
            raise ConfigError(f"max_views must be >= 1, got {self.max_views}")


@dataclass
class ViewRecord:
    """What happened to one input pair; errors are RMS in px where they apply."""

    index: int
    label: str
    status: ViewStatus
    held_out: bool = False
    params: tuple[float, ...] | None = None  # coverage.view_params: X, Y, size, skew
    rms_left: float | None = None
    rms_right: float | None = None
    rms_stereo: tuple[float, float] | None = None
    epipolar_rms_px: float | None = None
    reason: str | None = None


@dataclass
class CalibrationResult:
    """Everything the tool writes and reports."""

    calibration: StereoCalibration
    quality: CalibrationQuality
    rectification: RectifiedGeometry
    views: list[ViewRecord]
    coverage: tuple[float, ...]
    failures: list[str] = field(default_factory=list)
    sample_pair: tuple[np.ndarray, np.ndarray] | None = None
    model_scores: dict[str, float] = field(default_factory=dict)
    model_failures: dict[str, str] = field(default_factory=dict)
    sync: SyncReport | None = None

    @property
    def passed(self) -> bool:
        return not self.failures

    @property
    def dropped(self) -> list[ViewRecord]:
        return [v for v in self.views if v.status == "dropped"]


@dataclass(frozen=True)
class Progress:
    """Reported after each input pair."""

    view: ViewRecord
    kept: int
    held_out: int
    coverage: tuple[float, ...]


def _gate(calib: StereoCalibration, q: CalibrationQuality, config: SolveConfig) -> list[str]:
    failures = []
    stereo_rms = q.rms_stereo if q.rms_stereo is not None else float("inf")  # not measured: not passed
    epipolar = q.epipolar_rms_px if q.epipolar_rms_px is not None else float("inf")
    if stereo_rms > config.max_stereo_rms_px:
        failures.append(f"stereo RMS {stereo_rms:.3f} px > {config.max_stereo_rms_px} px")
    if epipolar > config.max_epipolar_rms_px:
        failures.append(f"held-out epipolar RMS {epipolar:.3f} px > {config.max_epipolar_rms_px} px")
    w, h = calib.image_size
    for side, K in (("left", calib.K_left), ("right", calib.K_right)):
        if not (0 <= K[0, 2] < w and 0 <= K[1, 2] < h):
            failures.append(f"{side} principal point ({K[0, 2]:.1f}, {K[1, 2]:.1f}) outside the image")
        aspect = K[1, 1] / K[0, 0]
        if not 1 / config.max_pixel_aspect <= aspect <= config.max_pixel_aspect:
            failures.append(f"{side} pixel aspect fy/fx = {aspect:.3f} outside "
                            f"[{1 / config.max_pixel_aspect:.3f}, {config.max_pixel_aspect:.3f}]")
    if not config.min_baseline_m <= calib.baseline_m <= config.max_baseline_m:
        failures.append(f"baseline {calib.baseline_m:.6g} m outside [{config.min_baseline_m:g}, "
                        f"{config.max_baseline_m:g}] m")
    return failures


def calibrate_pairs(pairs: Iterable[tuple[np.ndarray | None, np.ndarray | None]], board: Board,
                    config: SolveConfig = SolveConfig(), labels: Sequence[str] | None = None,
                    progress: Callable[[Progress], None] | None = None, select: bool = True) -> CalibrationResult:
    """Calibrate a stereo head from raw image pairs of `board` (see the module docstring).

    A pair given as None (an image that could not be read), whose sizes differ from each other or
    from the first pair's, or too small to hold the board (boards.too_small) is dropped with its
    reason. Raises BoardNotFoundError / TooFewViewsError when no solution can be computed; a
    solution that fails the gate is returned with `failures` set.
    """
    selector = CoverageSelector(config.min_distance)
    views: list[ViewRecord] = []
    found: list[tuple[int, str, dict[str, Detection], dict[str, Detection]]] = []
    sample: tuple[np.ndarray, np.ndarray] | None = None
    size: tuple[int, int] | None = None
    found_left = found_right = both = held = 0
    for index, (left, right) in enumerate(pairs):
        label = labels[index] if labels is not None else f"pair {index}"
        why = _unusable(left, right, size)
        if why is None and left is not None:  # an image too small for the board: dropped, said why
            why = too_small(left.shape, board)
        if why is not None:  # one bad file or odd size does not sink the set: dropped, named, said why
            views.append(ViewRecord(index, label, "dropped", reason=why))
            if progress is not None:
                progress(Progress(views[-1], len(found) - held, held, selector.coverage()))
            continue
        assert left is not None and right is not None  # _unusable names a missing image
        left, right = gray(left), gray(right)
        size = (left.shape[1], left.shape[0])
        dl, dr = detect_all(left, board), detect_all(right, board)
        found_left, found_right = found_left + bool(dl), found_right + bool(dr)
        view = ViewRecord(index, label, "no_board")
        matched = match_detections(dl, dr, board, ())
        if matched is not None:
            both += 1
            view.params = params = view_params(matched[1], board, size)
            held_here = both % config.holdout_every == 0
            if not select:
                selector.kept.append(params)
            if not select or held_here or selector.offer(params):
                view.status = "used"
                held += held_here
                found.append((index, label, dl, dr))
                sample = sample or (left, right)
            else:
                view.status = "redundant"
        views.append(view)
        if progress is not None:
            progress(Progress(view, len(found) - held, held, selector.coverage()))
        if select and len(found) - held >= config.max_views and held >= config.min_holdout:
            break
    if views and all(v.status == "dropped" for v in views):
        reasons = "; ".join(f"{v.label}: {v.reason}" for v in views[:3]) + ("; ..." if len(views) > 3 else "")
        raise UnusableImagesError(f"none of the {len(views)} pairs could be used ({reasons})")
    if both == 0:
        raise BoardNotFoundError(
            f"the {describe(board)} board was not found in both images of any of the "
            f"{len(views)} pairs (left found {found_left}, right found {found_right})")
    need = config.min_views if select else config.min_pairs
    if len(found) < need:
        what = "distinct views" if select else "pairs with the board in both images"
        raise TooFewViewsError(f"{len(found)} {what} from {both} pairs with the board; need {need} — "
                               f"move the board to new positions, distances and tilts")
    assert size is not None  # a pair with the board in both images set it
    order = choose_detector(found, size)
    kept = []
    for i, label, dl, dr in found:  # each was matched above, so the chosen detectors' corners match too
        matched = match_detections(dl, dr, board, order)
        assert matched is not None
        kept.append(PairPoints(i, label, *matched))
    return _solve(kept, views, size, selector.coverage(), sample, config)


def _unusable(left: np.ndarray | None, right: np.ndarray | None, size: tuple[int, int] | None) -> str | None:
    """Why a pair cannot be used (an image that could not be read, sizes that differ), or None."""
    if left is None or right is None:
        return f"cannot read the {'left' if left is None else 'right'} image"
    (lh, lw), (rh, rw) = left.shape[:2], right.shape[:2]
    if (lw, lh) != (rw, rh):
        return f"left {lw}x{lh} and right {rw}x{rh} differ"
    if size is not None and (lw, lh) != size:
        return f"{lw}x{lh}, not the set's {size[0]}x{size[1]}"
    return None


def match_detections(dl: dict[str, Detection], dr: dict[str, Detection], board: Board,
           order: Sequence[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Matched points of a pair, each image's corners from the first detector in `order` that found them."""
    if not dl or not dr:
        return None
    pick = [next((d[n] for n in order if n in d), next(iter(d.values()))) for d in (dl, dr)]
    return match_pair(pick[0], pick[1], board)


def choose_detector(found: Sequence[tuple[int, str, dict[str, Detection], dict[str, Detection]]],
                    size: tuple[int, int]) -> tuple[str, ...]:
    """The detectors the set's images are taken from, first choice first. Between the detectors
    (boards.CHESSBOARD_DETECTORS), the one whose corners fit a plumb_bob camera best on the left
    images both found (fewer than 4 such images: the one that found the most); a detector's refined
    corners (boards.REFINED) replace its own where they fit the two cameras better (the lens model
    that fits best, on each camera's images both have; see _better), judged on the set's own images:
    refinement helps where the detector's corners are off (a wide lens), and hurts where the
    squares' print pulls it (dot-coded squares)."""
    lefts, rights = [dl for _, _, dl, _ in found], [dr for _, _, _, dr in found]
    names = sorted({n for d in lefts for n in d} - set(REFINED.values()))
    first = names[0]
    for other in names[1:]:
        first = _better(first, other, (lefts,), size, ("plumb_bob",))
    variants = {n: _better(n, REFINED[n], (lefts, rights), size, MODELS) if n in REFINED else n for n in names}
    return (variants[first], *(variants[n] for n in names if n != first))


def _better(a: str, b: str, cameras: Sequence[Sequence[dict[str, Detection]]], size: tuple[int, int],
            models: Sequence[str]) -> str:
    """Of detections a and b, the one whose corners fit the cameras (each of `cameras` a list of one
    camera's detections) with the lower sum of RMS, on each camera's images both have, for the lens
    model that fits best; as fit_head does, a camera fitted over CROSS_START_RATIO times worse than
    the other is fitted again from the other's fit (ties and failures: a; fewer than 4 such images
    on every camera: the one found more often on the first camera)."""
    scored = [[d for d in images if a in d and b in d] for images in cameras]
    scored = [common for common in scored if len(common) >= 4]
    if not scored:
        return max((a, b), key=lambda n: sum(n in d for d in cameras[0]))
    totals: dict[str, float] = {}
    for n in (a, b):
        for model in models:
            try:
                fits = [calibrate_mono(model, [d[n].object_points for d in common],
                                       [d[n].image_points for d in common], size) for common in scored]
                if len(fits) == 2 and max(f.rms for f in fits) > CROSS_START_RATIO * min(f.rms for f in fits):
                    worse = int(fits[1].rms > fits[0].rms)
                    common = scored[worse]
                    fits[worse] = calibrate_mono(model, [d[n].object_points for d in common],
                                                 [d[n].image_points for d in common], size, fits[1 - worse])
            except LensSolveError:
                continue
            total = sum(f.rms for f in fits)
            totals[n] = min(total, totals.get(n, total))
    return min(totals, key=lambda n: totals[n]) if totals else a


def _solve(pairs: list[PairPoints], views: list[ViewRecord], size: tuple[int, int], coverage: tuple[float, ...],
           sample: tuple[np.ndarray, np.ndarray] | None, config: SolveConfig) -> CalibrationResult:
    models = MODELS if config.lens_model == "auto" else (config.lens_model,)
    try:
        kept, dropped = _screen(models, pairs, size, config)
        held = kept[config.holdout_every - 1::config.holdout_every]
        held_ids = {p.index for p in held}
        train = [p for p in kept if p.index not in held_ids]
        if len(held) < config.min_holdout or len(train) < 3:
            raise TooFewViewsError(f"{len(kept)} pairs left after removing outliers: too few to hold "
                                   f"{config.min_holdout} out and solve")
        choice = choose_model(models, train, held, size, config.model_tie)
        fit = _final_fit(choice, train, held, kept, size)
        held_errors = choice.held_errors
    except NoFitError as exc:
        if exc.unrectifiable:
            raise GateFailedError(_unrectifiable_failures(exc.unrectifiable, config), len(pairs)) from exc
        raise CalibrationError(f"the solver failed on {len(pairs)} pairs: {exc}") from exc
    except LensSolveError as exc:
        raise CalibrationError(f"the solver failed on {len(pairs)} pairs: {exc}") from exc
    by_index = {v.index: v for v in views}
    for index, reason in dropped.items():
        by_index[index].status, by_index[index].reason = "dropped", reason
    epi_all = []
    for i, p in enumerate(kept):
        v = by_index[p.index]
        v.rms_left, v.rms_right = float(fit.left.per_view[i]), float(fit.right.per_view[i])
        left_rms, right_rms = fit.stereo.per_view[i]
        v.rms_stereo = (float(left_rms), float(right_rms))
        epi_all.append(epipolar_dy(fit, p.left, p.right))
        v.epipolar_rms_px = rms(epi_all[-1])
    for p, e in zip(held, held_errors["epipolar"]):
        by_index[p.index].held_out = True
        by_index[p.index].epipolar_rms_px = float(e)
    quality = CalibrationQuality(
        rms_left=fit.left.rms, rms_right=fit.right.rms, rms_stereo=fit.stereo.rms,
        epipolar_rms_px=float(np.sqrt(np.mean(held_errors["epipolar"] ** 2))),
        epipolar_all_rms_px=rms(np.concatenate(epi_all)), views_used=len(kept), views_dropped=len(dropped),
        written=False, verified=False)
    failures = _gate(fit.calibration, quality, config)
    quality.passed = not failures
    return CalibrationResult(fit.calibration, quality, fit.geometry, views, coverage, failures, sample,
                             choice.scores, choice.failures, check_sync(fit, pairs))


def _unrectifiable_failures(fits: Sequence[UnrectifiableFitError], config: SolveConfig) -> list[str]:
    """The gate's verdict on fits that do not rectify: the lowest stereo RMS among them against the
    gate's limit (where it fails), and each model's rectification."""
    best = min(fits, key=lambda f: f.stereo_rms)
    out = []
    if best.stereo_rms > config.max_stereo_rms_px:
        out.append(f"stereo RMS {best.stereo_rms:.3f} px > {config.max_stereo_rms_px} px "
                   f"(the lowest of the lens models, {best.model})")
    return out + [f"no usable rectification: {f}" for f in fits]


def _final_fit(choice: ModelChoice, train: list[PairPoints], held: list[PairPoints], kept: list[PairPoints],
               size: tuple[int, int]) -> HeadFit:
    """The chosen model fitted on every pair kept; should that fit fail, the next model by held-out
    score (`choice` is updated to it, the failure listed)."""
    failures: list[LensSolveError] = []
    for model in sorted(choice.scores, key=lambda m: (m != choice.model, choice.scores[m])):
        try:
            start = choice.fit if model == choice.model else None
            fit = fit_head(model, kept, size, start)
        except LensSolveError as exc:
            choice.failures[model] = f"fitted without the held-out pairs, but not with them: {exc}"
            failures.append(exc)
            continue
        if model != choice.model:
            choice.held_errors = held_out_errors(fit_head(model, train, size), held)
            choice.model = model
        return fit
    raise NoFitError("; ".join(map(str, failures)), failures)


def _screen(models: Sequence[str], pairs: list[PairPoints], size: tuple[int, int], config: SolveConfig
            ) -> tuple[list[PairPoints], dict[int, str]]:
    """Outlier removal with the first model that fits (the most flexible pinhole model first:
    rational, then equidistant, then plumb_bob; or the one model asked for)."""
    order = [m for m in ("rational_polynomial", "equidistant", "plumb_bob") if m in models]
    failures: list[LensSolveError] = []
    for model in order:
        try:
            _, kept, dropped = robust_fit(model, pairs, size, config.outliers)
            return kept, dropped
        except LensSolveError as exc:
            failures.append(exc)
    raise NoFitError("; ".join(map(str, failures)), failures)
