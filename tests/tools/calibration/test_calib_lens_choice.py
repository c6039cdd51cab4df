"""Lens-model choice and outlier removal on synthetic corners projected through known lenses.

Corners (not rendered images) so that strong lenses can be simulated exactly: a wide-angle
rational lens, an equidistant fisheye, and the plain plumb_bob lens of the simulated units.
"""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from stereocam.device_sim.calibration.acceptance import firmware_map
from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.calibration_limits import CalibrationImplausible, check_rectifiable
from stereocam.tools.calibration.fit import (
    OutlierRules, PairPoints, UnrectifiableFitError, choose_model, fit_head, robust_fit,
)
from stereocam.tools.calibration.lens import MODELS, LensSolveError, rectify_map

SIZE = (1280, 640)
K = np.array([[520.0, 0.0, 641.0], [0.0, 522.0, 318.0], [0.0, 0.0, 1.0]])
R_LR = cv2.Rodrigues(np.array([0.01, -0.02, 0.005]))[0]
T_LR = np.array([-0.06, 0.0005, 0.001])
LENSES = {
    "plumb_bob": np.array([-0.05, 0.02, 0.0005, -0.0003, 0.0]),
    "rational_polynomial": np.array([0.1, 0.0, 0.0002, 0.0001, 0.0, 0.4, 0.0, 0.0]),
    "equidistant": np.array([0.02, -0.01, 0.003, -0.001]),
}
GRID = np.array([[i * 0.03, j * 0.03, 0.0] for j in range(7) for i in range(10)])


def _project(model: str, pts_cam: np.ndarray, D: np.ndarray) -> np.ndarray:
    if model == "equidistant":
        return cv2.fisheye.projectPoints(pts_cam.reshape(-1, 1, 3), np.zeros((3, 1)), np.zeros((3, 1)), K, D)[0]
    return cv2.projectPoints(pts_cam, np.zeros(3), np.zeros(3), K, D)[0]


def synthetic_pairs(model: str, n: int = 30, noise: float = 0.1, seed: int = 0,
                    late: tuple[int, ...] = (), lens: np.ndarray | None = None) -> list[PairPoints]:
    """Board views through the lens; in the pairs `late` the right camera sees the board 2 mm and
    0.3 degrees further on (a frame not taken at the same instant as the left one)."""
    rng = np.random.default_rng(seed)
    moved = cv2.Rodrigues(np.array([0.0, 0.005, 0.0]))[0]
    pairs = []
    while len(pairs) < n:
        R = cv2.Rodrigues(rng.uniform(-0.6, 0.6, 3))[0]
        t = np.array([rng.uniform(-0.5, 0.4), rng.uniform(-0.3, 0.2), rng.uniform(0.35, 0.9)])
        left_cam = GRID @ R.T + t
        board_right = (GRID @ moved.T + [0.002, 0.0, 0.0]) @ R.T + t if len(pairs) in late else left_cam
        right_cam = board_right @ R_LR.T + T_LR
        if left_cam[:, 2].min() < 0.1 or right_cam[:, 2].min() < 0.1:
            continue
        D = LENSES[model] if lens is None else lens
        uv = [_project(model, p, D).reshape(-1, 2) for p in (left_cam, right_cam)]
        if any(np.any(u < 5) or np.any(u[:, 0] > SIZE[0] - 6) or np.any(u[:, 1] > SIZE[1] - 6) for u in uv):
            continue
        l, r = (u + rng.normal(0, noise, u.shape) for u in uv)
        pairs.append(PairPoints(len(pairs), f"pair {len(pairs)}", GRID.astype(np.float32),
                                l.astype(np.float32), r.astype(np.float32)))
    return pairs


@pytest.mark.parametrize("truth", list(LENSES))
def test_the_lens_model_is_chosen_on_held_out_pairs(truth: str) -> None:
    pairs = synthetic_pairs(truth)
    held, train = pairs[4::5], [p for i, p in enumerate(pairs) if i % 5 != 4]
    choice = choose_model(MODELS, train, held, SIZE, 0.05)
    chosen, scores, errors = choice.model, choice.scores, choice.held_errors
    if truth == "plumb_bob":
        assert chosen == "plumb_bob"  # the more complex models fit as well: the simpler wins the tie
    else:
        # both other models describe a barrel wide-angle lens about equally: either may win, never plumb_bob
        assert chosen != "plumb_bob" and scores["plumb_bob"] > 1.4 * scores[chosen]
    fit = fit_head(chosen, pairs, SIZE, fit_head("plumb_bob", pairs, SIZE))
    assert abs(fit.calibration.baseline_m / np.linalg.norm(T_LR) - 1) < 0.005
    assert abs(fit.calibration.K_left[0, 0] / K[0, 0] - 1) < 0.005
    assert np.sqrt(np.mean(errors["epipolar"] ** 2)) < 0.3


def test_non_simultaneous_pairs_are_dropped_by_their_residuals() -> None:
    pairs = synthetic_pairs("plumb_bob", n=24, seed=3, late=(5, 17))
    fit, kept, dropped = robust_fit("plumb_bob", pairs, SIZE, OutlierRules())
    assert sorted(dropped) == [5, 17]
    assert all("stereo" in why or "epipolar" in why for why in dropped.values())
    assert len(kept) == 22 and fit.stereo.rms < 0.2


def test_a_gross_outlier_that_spoils_the_rectification_is_still_dropped() -> None:
    """One pair's right view from another pair: the full rational fit of all pairs has no usable
    rectification (the camera would not store it), yet screening still finds the pair by its residuals."""
    pairs = synthetic_pairs("rational_polynomial", n=16, seed=2)
    p = pairs[3]
    pairs[3] = PairPoints(p.index, p.label, p.obj, p.left, pairs[4].right)
    with pytest.raises(UnrectifiableFitError):
        fit_head("rational_polynomial", pairs, SIZE, reduce=False)  # all 8 coefficients free
    _, kept, dropped = robust_fit("rational_polynomial", pairs, SIZE, OutlierRules())
    assert list(dropped) == [3] and len(kept) == 15
    fit_head("rational_polynomial", kept, SIZE)  # the rest rectifies


# -- the camera's own rule: a lens model that folds the image is no fit -----------------------------

def _head(D: np.ndarray, model: str = "plumb_bob") -> StereoCalibration:
    return StereoCalibration(SIZE, K, D, K, D, R_LR, T_LR, model)


FOLD_CASES = {  # lens -> whether the firmware can rectify it
    "mild barrel": (_head(np.array([-0.05, 0.0, 0.0, 0.0, 0.0])), True),
    "rational": (_head(LENSES["rational_polynomial"], "rational_polynomial"), True),
    "fisheye": (_head(LENSES["equidistant"], "equidistant"), True),
    "folds at the corners": (_head(np.array([-0.2, 0.0, 0.0, 0.0, 0.0])), False),
    "folds everywhere": (_head(np.array([-0.5, 0.0, 0.0, 0.0, 0.0])), False),
    "rational fold": (_head(np.array([-0.2, 0.0, 0.0, 0.0, 0.0, 0.1, 0.0, 0.0]), "rational_polynomial"), False),
}


@pytest.mark.parametrize("case", sorted(FOLD_CASES))
def test_the_tool_judges_rectifiability_with_the_firmware_rule(case) -> None:
    """OpenCV's maps on the host and the firmware's own maps meet the one rule alike (SPEC §12.4)."""
    calib, usable = FOLD_CASES[case]
    verdicts = []
    for build in (rectify_map, firmware_map):
        try:
            check_rectifiable(calib, build)
            verdicts.append(None)
        except CalibrationImplausible as exc:
            verdicts.append(str(exc))
    assert (verdicts[0] is None) == (verdicts[1] is None) == usable, verdicts


def test_a_fit_whose_lens_folds_the_image_is_no_fit() -> None:
    """Corners seen only near the centre fit a lens that folds outside them: the fit is refused,
    so model choice passes it over and the tool never writes what the camera would refuse."""
    pairs = synthetic_pairs("plumb_bob", n=12, noise=0.02, seed=5, lens=np.array([-0.2, 0.0, 0.0, 0.0, 0.0]))
    with pytest.raises(LensSolveError, match="folds|sees the sensor"):
        fit_head("plumb_bob", pairs, SIZE)
