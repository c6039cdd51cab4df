"""The matching stage: the engine the ``algorithm`` parameter selects, configured from the device
parameters (SPEC §5.1) through the engine table (stereocam.stereo.engines), then the post-processing
chain (SPEC §5.3, stereocam.stereo.post) when the configuration turns a stage on."""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from stereocam.stereo.engines import StereoMatcher, matcher_for
from stereocam.stereo.post import PostChain, PostParams, post_params_from_config
from stereocam.stereo.post.lr_check import right_view_disparity

TRIGGER_GAP_PERIODS = 3
"""The temporal filter forgets its past when captures are further apart than this many frame
periods (1 / fps): a trigger gap, a stream stopped and started."""


class StereoStage:
    """Disparity of a rectified pair; the matcher is rebuilt only when its settings or the format
    change, the post-processing chain (and its temporal state) when the configuration changes."""

    def __init__(self) -> None:
        self._matcher: StereoMatcher | None = None
        self._mirror: StereoMatcher | None = None  # the same engine on the mirrored pair (lr_check)
        self._chain: PostChain | None = None
        self._chain_cfg: dict[str, int] = {}
        self._last_at: float | None = None

    def disparity(self, cfg: Mapping[str, int], left: np.ndarray, right: np.ndarray,
                  at: float | None = None) -> np.ndarray:
        """``at``: the capture's exposure instant (s), to find trigger gaps; None: not known (replay)."""
        return self.planes(cfg, left, right, at)[0]

    def planes(self, cfg: Mapping[str, int], left: np.ndarray, right: np.ndarray, at: float | None = None,
               with_confidence: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        """The disparity plane and, ``with_confidence``, the confidence plane (SPEC §5.3)."""
        self._matcher = matcher_for(cfg, left.shape, self._matcher)
        disp = self._matcher.match(left, right)
        chain = self._post_chain(cfg, at)
        if chain is None and not with_confidence:
            return disp, None
        if chain is None:
            chain = PostChain(PostParams(), cfg.get("min_disparity", 0))  # every stage off

        def right_view() -> np.ndarray:
            self._mirror = matcher_for(cfg, left.shape, self._mirror)
            return right_view_disparity(self._mirror.match, left, right)
        disp = chain.run(disp, right_view, with_confidence)
        return disp, chain.confidence if with_confidence else None

    def _post_chain(self, cfg: Mapping[str, int], at: float | None) -> PostChain | None:
        """The chain for ``cfg`` (None: every stage off); its temporal state reset on a
        configuration change or a trigger gap."""
        gap = (at is not None and self._last_at is not None
               and at - self._last_at > TRIGGER_GAP_PERIODS / max(cfg.get("fps", 1), 1))
        self._last_at = at
        if self._chain is None or cfg != self._chain_cfg:
            params = post_params_from_config(cfg)
            self._chain = PostChain(params, cfg.get("min_disparity", 0)) if params.active else None
            self._chain_cfg = dict(cfg)
        elif gap:
            self._chain.reset()
        return self._chain
