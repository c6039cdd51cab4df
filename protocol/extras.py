"""The optional install groups (pip extras, pyproject.toml): which one provides each optional
third-party module, and the error that names it when a feature finds its module missing.

The SDK alone (``pip install stereocam``) opens cameras; the rest is opt-in:
``sim`` (the simulated camera), ``recording`` (MCAP files, rematch), ``viewer`` (pictures and the
live viewer), ``factory`` (calibration and the factory record), ``all`` (everything).
"""
from __future__ import annotations

from typing import NoReturn

from .errors import MissingExtraError

EXTRA_OF: dict[str, str] = {
    "numba": "sim",
    "mcap": "recording", "mcap_ros2": "recording", "zstandard": "recording", "dask": "recording",
    "distributed": "recording",
    "cv2": "viewer", "matplotlib": "viewer",
    "psycopg": "factory",
}
"""top-level module name -> the extra that installs it"""


def raise_missing(exc: ModuleNotFoundError, feature: str) -> NoReturn:
    """Re-raise a failed import of ``feature``: as MissingExtraError naming the extra when the missing
    module belongs to one, else unchanged (a missing module of our own is a bug, not an install choice)."""
    extra = EXTRA_OF.get((exc.name or "").partition(".")[0])
    if extra is None:
        raise exc
    raise MissingExtraError(f"{feature} needs the {exc.name!r} package: pip install 'stereocam[{extra}]'") from exc
