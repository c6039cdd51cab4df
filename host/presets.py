"""Presets: a camera's whole configuration as a JSON file (``Camera.save_preset`` / ``load_preset``),
or a named combination of matching and post-processing settings (``POST_PRESETS``: 'high_density',
'high_accuracy', 'off'; stereocam.stereo.post.presets) that changes only the values it names."""
from __future__ import annotations

import json
import os
from pathlib import Path

from stereocam.protocol.errors import ConfigError
from stereocam.stereo.post.presets import POST_PRESETS, preset_config

PRESET_FORMAT = "stereocam-preset/1"


def write_preset(path: str | os.PathLike, config: dict[str, int], model: str = "") -> None:
    """``{"format": ..., "model": ..., "config": {name: value}}``, indented, one file."""
    doc = {"format": PRESET_FORMAT, "model": model, "config": config}
    try:
        Path(path).write_text(json.dumps(doc, indent=2) + "\n")
    except (OSError, TypeError) as exc:
        raise ConfigError(f"cannot write preset {path!r}: {exc}") from exc


def read_preset(path: str | os.PathLike) -> dict[str, int]:
    """The configuration a preset file holds; ConfigError if it is unreadable or not a preset."""
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, ValueError, TypeError) as exc:
        raise ConfigError(f"cannot read preset {path}: {exc}") from exc
    if not isinstance(doc, dict) or doc.get("format") != PRESET_FORMAT or not isinstance(doc.get("config"), dict):
        raise ConfigError(f"{path} is not a stereocam preset (expected format {PRESET_FORMAT!r})")
    return doc["config"]


def preset_values(preset: str | os.PathLike) -> dict[str, int]:
    """The values a preset sets: a name of ``POST_PRESETS``, else a preset file's configuration."""
    if isinstance(preset, str) and (preset in POST_PRESETS or not preset or (
            not Path(preset).exists() and "/" not in preset and os.sep not in preset
            and not preset.lower().endswith(".json"))):
        return preset_config(preset)  # a name (ConfigError naming the known ones when unknown)
    return read_preset(preset)
