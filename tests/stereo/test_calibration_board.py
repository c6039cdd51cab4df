"""Board geometry lives outside the simulator: calibration and rematch tools load no simulator module."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from stereocam.stereo.calibration_board import BoardSpec
from stereocam.protocol.errors import ConfigError
from tests.support.paths import REPO


def test_board_geometry() -> None:
    board = BoardSpec(3, 2, 0.05, margin_squares=0.5)
    pts = board.object_points()
    assert pts.shape == (6, 3) and pts.dtype == np.float32
    assert np.allclose(pts[[0, 1, 3]], [[0, 0, 0], [0.05, 0, 0], [0, 0.05, 0]])  # x fastest
    assert np.allclose(board.outline()[[0, 2]], [[-0.075, -0.075, 0], [0.175, 0.125, 0]])
    with pytest.raises(ConfigError, match="bad board 1x2"):
        BoardSpec(1, 2, 0.05)


def test_hardware_tools_load_no_simulator_module() -> None:
    code = ("import sys, stereocam.tools.calibration.solve, stereocam.tools.calibration.boards, "
            "stereocam.tools.calibration.coverage, "
            "stereocam.tools.recording.rematch, stereocam.tools.recording.rematch_tasks; "
            "print(sorted(n for n in sys.modules if n.startswith('stereocam.device_sim')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"
