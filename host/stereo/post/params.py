"""Post-processing parameters: one field per stage, read from the device configuration (SPEC §5.1
ids 30..39, §5.3) through ``POST_CONFIG`` rows, so every limit lives once, in protocol/params.py."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from stereocam.protocol.params import BY_NAME

from ..config_map import ConfigField, check_params, params_from_config

POST_CONFIG: tuple[ConfigField, ...] = tuple(ConfigField(name) for name in (
    "lr_check", "hole_fill", "spatial_alpha", "spatial_delta", "spatial_iterations", "temporal_alpha",
    "temporal_delta", "temporal_persistence", "median_size", "decimation"))
"""Device configuration key -> PostParams field (the same names)."""


def _default(name: str) -> int:
    return int(BY_NAME[name].default)


@dataclass(frozen=True)
class PostParams:
    """The chain's settings; the defaults (the protocol's) turn every stage off."""

    lr_check: int = _default("lr_check")  # px tolerance of the left-right check; -1 off
    hole_fill: int = _default("hole_fill")  # 0 off, 1 nearest in the row, 2 background along 8 paths
    spatial_alpha: int = _default("spatial_alpha")  # 1/256: weight of the current pixel; 0 off
    spatial_delta: int = _default("spatial_delta")  # 1/16 px: larger steps are edges
    spatial_iterations: int = _default("spatial_iterations")
    temporal_alpha: int = _default("temporal_alpha")  # 1/256: weight of the new frame; 0 off
    temporal_delta: int = _default("temporal_delta")  # 1/16 px
    temporal_persistence: int = _default("temporal_persistence")  # frames an invalid pixel holds its value
    median_size: int = _default("median_size")  # 3, 5; 1 off
    decimation: int = _default("decimation")  # block side; 1 off

    def __post_init__(self) -> None:
        check_params(self, POST_CONFIG)

    @property
    def active(self) -> bool:
        """Whether any stage runs."""
        return self != PostParams()

    @property
    def needs_right_view(self) -> bool:
        """The left-right check needs the right view's disparity (the mirrored pair matched)."""
        return self.lr_check >= 0


def post_params_from_config(cfg: Mapping[str, int]) -> PostParams:
    """The chain's settings from a device configuration (keys missing, as before 1.3: stage off)."""
    full = {f.key: cfg.get(f.key, _default(f.key)) for f in POST_CONFIG}
    return params_from_config(PostParams, POST_CONFIG, full)
