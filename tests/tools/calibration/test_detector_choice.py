"""The set chooses its corners: between the detectors, and between a detector's corners and their
sub-pixel refinement, by how well each fits a camera on the set's own images."""
from __future__ import annotations

import numpy as np
import pytest

from stereocam.device_sim.calibration.board import board_poses
from stereocam.device_sim.calibration.rays import lens_project
from stereocam.device_sim.calibration.truth import true_calibration
from stereocam.stereo.calibration_board import BoardSpec
from stereocam.tools.calibration.boards import Detection
from stereocam.tools.calibration.solve import choose_detector

BOARD = BoardSpec(9, 6, 0.03)
TRUTH = true_calibration(3, (640, 480))


def _found(off_px: dict[str, float], missing: dict[str, int] | None = None) -> list:
    """Left/right detections of 8 poses, each detector's corners off the truth by Gaussian noise of
    the given sigma (px); `missing` drops a detector from that many of the first images."""
    rng = np.random.default_rng(4)
    out = []
    for i, pose in enumerate(board_poses(3, 8, BOARD, TRUTH, distance_m=(0.4, 0.9))):
        exact = lens_project(TRUTH.K_left, TRUTH.D_left, TRUTH.lens_model, BOARD.object_points() @ pose.R.T + pose.t)
        d = {n: Detection(np.arange(len(exact)), (exact + rng.normal(0, s, exact.shape)).astype(np.float32),
                          BOARD.object_points())
             for n, s in off_px.items() if i >= (missing or {}).get(n, 0)}
        out.append((i, f"pair {i}", d, d))
    return out


@pytest.mark.parametrize("raw, refined, first", [(1.0, 0.05, "sector_subpix"), (0.05, 0.5, "sector")])
def test_refined_corners_are_used_only_where_they_fit_better(raw: float, refined: float, first: str) -> None:
    assert choose_detector(_found({"sector": raw, "sector_subpix": refined}), TRUTH.image_size)[0] == first


def test_the_better_detector_comes_first_and_the_other_keeps_its_better_corners() -> None:
    found = _found({"classic": 0.05, "sector": 1.0, "sector_subpix": 0.1})
    assert choose_detector(found, TRUTH.image_size) == ("classic", "sector_subpix")
    few = _found({"classic": 0.05, "sector": 1.0, "sector_subpix": 0.1}, missing={"classic": 6})
    assert choose_detector(few, TRUTH.image_size)[0] == "sector_subpix"  # too few common: the one found more
