"""Simulators served on this machine (over TCP or a pty) announce themselves in a per-user runtime
directory, one JSON file per serving process, removed when it stops; ``discover()`` reads them.

The directory is ``$XDG_RUNTIME_DIR/stereocam`` if that variable is set, else
``<tempdir>/stereocam-<uid>`` (mode 0700). A file whose process is gone (killed without cleanup)
is ignored and removed by the next reader.
"""
from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Iterator

if TYPE_CHECKING:
    from ..discovery import DeviceEntry


def runtime_dir() -> Path:
    base = os.environ.get("XDG_RUNTIME_DIR")
    return Path(base) / "stereocam" if base else Path(tempfile.gettempdir()) / f"stereocam-{os.getuid()}"


@contextlib.contextmanager
def announce(url: str, serial: str, model: str, firmware: str, transport: str) -> Iterator[Path]:
    """While the block runs, ``discover()`` in any process of this user lists the camera at ``url``."""
    folder = runtime_dir()
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    path = folder / f"served-{os.getpid()}.json"
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps({"url": url, "serial": serial, "model": model, "firmware": firmware,
                               "transport": transport, "pid": os.getpid()}))
    tmp.replace(path)  # readers never see half a file
    try:
        yield path
    finally:
        path.unlink(missing_ok=True)


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` exists (one of another user counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def discover() -> list["DeviceEntry"]:
    """The cameras announced by live serving processes of this user."""
    from ..discovery import DeviceEntry

    entries = []
    folder = runtime_dir()
    for path in sorted(folder.glob("served-*.json")) if folder.is_dir() else []:
        try:
            doc = json.loads(path.read_text())
            pid = int(doc["pid"])
        except (OSError, ValueError, KeyError, TypeError):
            continue  # being written or removed right now, or not ours
        if not pid_alive(pid):
            path.unlink(missing_ok=True)
            continue
        entries.append(DeviceEntry(doc["url"], doc.get("serial"), doc.get("model"), doc.get("transport", "serial"),
                                   doc.get("firmware"), simulated=True, location=f"served by pid {pid}"))
    return entries
