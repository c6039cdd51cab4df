"""Board detections kept on disk between runs, where ``STEREOCAM_DETECTION_CACHE`` names a folder.

Chessboard detection is most of an offline calibration's time; re-running one on the same images
(another gate, another lens model, a factory re-check, an OpenCV comparison) then detects nothing
twice. An entry is keyed by the grey image's bytes, the board, OpenCV's version and the detector
code (``boards.py``), so a change to any of them misses. Entries are written whole (a temporary file
renamed), so runs in parallel can share the folder; an unreadable entry is a miss and is rewritten.
Off unless the variable is set.
"""
from __future__ import annotations

import hashlib
import os
import tempfile
import zipfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np

ENV = "STEREOCAM_DETECTION_CACHE"
Arrays = tuple[np.ndarray, ...]
_CODE = hashlib.sha256(Path(__file__).with_name("boards.py").read_bytes()).hexdigest()[:16]


def entry(gray: np.ndarray, board: str) -> Path | None:
    """The cache file for this image and board, or None when caching is off."""
    folder = os.environ.get(ENV)
    if not folder:
        return None
    h = hashlib.sha256(f"{board}|{cv2.__version__}|{_CODE}|{gray.shape}|{gray.dtype}".encode())
    h.update(np.ascontiguousarray(gray).data)
    return Path(folder) / f"{h.hexdigest()}.npz"


def load(path: Path | None) -> dict[str, Arrays] | None:
    """Each detector's arrays from the entry, or None on a miss."""
    if path is None or not path.exists():
        return None
    try:
        with np.load(path) as z:
            names = sorted({k.split("/")[0] for k in z.files})
            return {n: tuple(z[f"{n}/{i}"] for i in range(int(z[f"{n}/count"]))) for n in names}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None


def store(path: Path | None, found: dict[str, Arrays]) -> None:
    """Write the entry whole (no-op when caching is off); a folder that cannot be written is skipped."""
    if path is None:
        return
    arrays: dict[str, Any] = {f"{n}/{i}": a for n, arrs in found.items() for i, a in enumerate(arrs)}
    arrays.update({f"{n}/count": np.array(len(arrs)) for n, arrs in found.items()})
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
        os.replace(tmp, path)
    except OSError:
        return
