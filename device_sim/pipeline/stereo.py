"""The matching stage: the engine the ``algorithm`` parameter selects, configured from the device
parameters (SPEC §5.1) through the engine table (stereocam.stereo.engines)."""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from stereocam.stereo.engines import StereoMatcher, matcher_for


class StereoStage:
    """Disparity of a rectified pair; the matcher is rebuilt only when its settings or the format change."""

    def __init__(self) -> None:
        self._matcher: StereoMatcher | None = None

    def disparity(self, cfg: Mapping[str, int], left: np.ndarray, right: np.ndarray) -> np.ndarray:
        self._matcher = matcher_for(cfg, left.shape, self._matcher)
        return self._matcher.match(left, right)
