"""Presets: a camera's whole configuration as a JSON file (``Camera.save_preset`` / ``load_preset``),
or a named combination of matching and post-processing settings (``POST_PRESETS``: 'high_density',
'high_accuracy', 'off'; stereocam.stereo.post.presets) that changes only the values it names."""
from __future__ import annotations

import json
import os
import stat
import uuid
from pathlib import Path

from stereocam.input_files import read_regular
from stereocam.protocol.errors import ConfigError, MissingInputError
from stereocam.stereo.post.presets import POST_PRESETS, preset_config

PRESET_FORMAT = "stereocam-preset/1"
MAX_PRESET_BYTES = 1 << 20  # a preset is a few KB: a larger file is refused unread


def _replace_whole(path: Path, data: bytes) -> None:
    """Write ``data`` to a new file beside ``path`` (synced), then rename it over ``path``: the old
    file stays whole until the new one is. A link is followed; a folder, FIFO or device is refused."""
    target = Path(os.path.realpath(path))
    try:
        old: os.stat_result | None = os.stat(target)
    except FileNotFoundError:
        old = None
    if old is not None and not stat.S_ISREG(old.st_mode):
        raise ConfigError(f"cannot write preset {str(path)!r}: it is not a regular file (a folder, a FIFO or a device)")
    tmp = target.with_name(f".{target.name}.{uuid.uuid4().hex[:12]}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)  # exclusive: never through a link
    try:
        with os.fdopen(fd, "wb") as f:
            if old is not None:
                os.fchmod(f.fileno(), stat.S_IMODE(old.st_mode))
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_preset(path: str | os.PathLike, config: dict[str, int], model: str = "") -> None:
    """``{"format": ..., "model": ..., "config": {name: value}}``, indented, one file, replaced whole
    (a failed write keeps the previous file as it was)."""
    doc = {"format": PRESET_FORMAT, "model": model, "config": config}
    try:
        data = (json.dumps(doc, indent=2) + "\n").encode()
    except (TypeError, ValueError) as exc:  # before any file is touched
        raise ConfigError(f"cannot write preset {path!r}: {exc}") from exc
    try:
        _replace_whole(Path(path), data)
    except TypeError as exc:
        raise ConfigError(f"cannot write preset {path!r}: {exc}") from exc
    except OSError as exc:  # said without the temporary file's name
        raise ConfigError(f"cannot write preset {path!r}: {exc.strerror or exc}") from exc


def read_preset(path: str | os.PathLike) -> dict[str, int]:
    """The configuration a preset file holds; ConfigError if it is missing, not a regular file,
    larger than MAX_PRESET_BYTES, unreadable or not a preset (a FIFO or a device is never read)."""
    try:
        doc = json.loads(read_regular(Path(path), what="preset", limit=MAX_PRESET_BYTES, error=ConfigError))
    except MissingInputError as exc:
        raise ConfigError(f"cannot read preset {path}: it does not exist") from exc
    except ConfigError:
        raise  # refused unread (not a regular file, too large): the message names the path
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
