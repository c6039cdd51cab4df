"""What every command shares: leave the camera as found, write outputs only where allowed."""
from __future__ import annotations

import contextlib
import tempfile
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
        if cam.alive:
            cam.stop()
            changed = {k: v for k, v in cam.config().items() if found.get(k) != v}
            if changed:
                cam.configure(**{k: found[k] for k in changed})


def writable_dir(path: Path, keep: bool = True) -> Path:
    """Create ``path`` (and parents) and write a file into it now; OSError naming the folder if either
    fails (permission bits say nothing to root, and a file system may be read-only or full). With
    ``keep=False`` the folders made for the test are removed again: nothing is left behind."""
    made = [p for p in (path, *path.parents) if not p.exists()]
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as exc:
        raise OSError(exc.errno, f"cannot write into directory {str(path)!r}: {exc.strerror or exc}") from exc
    finally:
        for folder in made if not keep else ():
            with contextlib.suppress(OSError):
                folder.rmdir()
    return path


def output_dir(path: Path, option: str = "--out") -> Path:
    """``writable_dir`` before any camera is touched, as a usage error (exit 2) naming ``option``."""
    try:
        return writable_dir(path)
    except OSError as exc:
        raise click.BadParameter(exc.strerror or str(exc), param_hint=f"'{option}'") from exc
