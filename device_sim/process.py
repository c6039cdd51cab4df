"""A simulator in a child process (``python -m stereocam.device_sim --serve SPEC``), for tests and benches."""
from __future__ import annotations

import os
import signal
import subprocess
import sys


class ServedSimulator:
    """Starts the child and reads the URL it prints first; ``stop`` sends SIGTERM and waits."""

    def __init__(self, spec: str, seed: int | None = 7, scene: str = "lab",
                 extra: list[str] | tuple[str, ...] | None = None, flash: str | os.PathLike[str] | None = None,
                 env: dict[str, str] | None = None):
        """``extra``: more command-line options (``--trigger-line NAME``, ``--truth-log PATH``, ...);
        ``flash``: the unit's flash file (kept across restarts); ``env``: added to the environment;
        ``seed`` None: the simulator picks a free one (a serial no other served simulator has)."""
        extra = [*(extra or []), *(["--flash", os.fspath(flash)] if flash is not None else [])]
        self.proc = subprocess.Popen([sys.executable, "-m", "stereocam.device_sim", "--serve", spec,
                                      *(["--seed", str(seed)] if seed is not None else []),
                                      "--scene", scene, *extra],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     env={**os.environ, **(env or {}), "PYTHONUNBUFFERED": "1"})
        out, err = self.proc.stdout, self.proc.stderr
        assert out is not None and err is not None  # both are pipes
        self.url = out.readline().strip()
        if not self.url:
            raise RuntimeError(f"simulator did not start: {err.read()}")

    def stop(self) -> int:
        self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(timeout=10)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()

    def __enter__(self) -> "ServedSimulator":
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
