"""Private flash files for simulators started without ``--flash PATH``, that never pile up.

Each private flash lives in its own folder under one per-user state directory. The process that
owns a folder holds an exclusive ``flock`` on a lock file inside it for as long as it lives; the
kernel drops that lock whatever ends the process (SIGKILL included). Every new private flash first
sweeps the folders whose lock it can take: their owner is gone. A clean close removes its own
folder at once, so a SIGKILLed simulator leaks one folder at most until the next one starts.
"""
from __future__ import annotations

import fcntl
import os
import re
import shutil
import tempfile
import time
import weakref
from pathlib import Path

LOCK_NAME = "owner.lock"
SETUP_PREFIX = ".setup-"  # a folder is locked under this name, then renamed: a sweep never sees it unlocked
SETUP_GRACE_S = 60.0


def state_dir() -> Path:
    """The per-user folder holding every private flash (``$XDG_RUNTIME_DIR/stereocam-flash`` or
    ``<tmp>/stereocam-flash-<uid>``)."""
    base = os.environ.get("XDG_RUNTIME_DIR")
    return Path(base) / "stereocam-flash" if base else Path(tempfile.gettempdir()) / f"stereocam-flash-{os.getuid()}"


def sweep(root: Path) -> int:
    """Remove the folders under ``root`` whose owner process is gone; how many were removed."""
    removed = 0
    for folder in root.iterdir():
        if folder.name.startswith(SETUP_PREFIX):  # not locked yet: only a long-dead one is stale
            try:
                stale = time.time() - folder.stat().st_mtime > SETUP_GRACE_S
            except FileNotFoundError:
                continue
            if stale:
                shutil.rmtree(folder, ignore_errors=True)
            continue
        lock = folder / LOCK_NAME
        try:
            fd = os.open(lock, os.O_RDWR)
        except FileNotFoundError:  # a folder being set up right now, or a stray: leave it
            continue
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)  # its owner is alive
            continue
        shutil.rmtree(folder, ignore_errors=True)
        os.close(fd)
        removed += 1
    return removed


class ScratchFlash:
    """One private flash file; removed by ``cleanup`` (or by the next sweep if the process dies)."""

    def __init__(self, name: str, root: Path | None = None):
        self.root = root or state_dir()
        self.root.mkdir(mode=0o700, parents=True, exist_ok=True)
        sweep(self.root)
        setup = Path(tempfile.mkdtemp(prefix=SETUP_PREFIX, dir=self.root))
        self._lock_fd = os.open(setup / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o600)
        fcntl.flock(self._lock_fd, fcntl.LOCK_EX)
        self.folder = self.root / f"{os.getpid()}-{setup.name[len(SETUP_PREFIX):]}"
        setup.rename(self.folder)
        self.path = self.folder / (re.sub(r"[^A-Za-z0-9_.-]", "_", name)[:64] + ".flash")  # a serial names it
        # also at garbage collection and interpreter exit, as tempfile.TemporaryDirectory does
        self._remove = weakref.finalize(self, _remove, self.folder, self._lock_fd)

    def cleanup(self) -> None:
        """Remove the folder and release the lock (idempotent)."""
        self._remove()


def _remove(folder: Path, lock_fd: int) -> None:
    shutil.rmtree(folder, ignore_errors=True)
    os.close(lock_fd)
