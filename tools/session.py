"""What every command shares: leave the camera as found, write outputs only where allowed."""
from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Iterator

import click

import stereocam


@contextlib.contextmanager
def preserved_configuration(cam: stereocam.Camera) -> Iterator[dict[str, int]]:
    """Inside, change anything; after, the stream is stopped and every parameter that changed is
    put back (trigger mode included), also after an error or Ctrl-C. Yields the configuration found."""
    found = cam.config()
    try:
        yield found
    finally:
        if cam.link.alive:
            cam.stop()
            changed = {k: v for k, v in cam.config().items() if found.get(k) != v}
            if changed:
                cam.configure(**{k: found[k] for k in changed})


def output_dir(path: Path) -> Path:
    """Create ``path`` (and parents) now, before any camera is touched; BadParameter (exit 2) if it
    cannot be created or written."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise click.BadParameter(f"cannot create directory {str(path)!r}: {exc.strerror or exc}",
                                 param_hint="'--out'") from exc
    if not os.access(path, os.W_OK | os.X_OK):
        raise click.BadParameter(f"directory {str(path)!r} is not writable", param_hint="'--out'")
    return path
