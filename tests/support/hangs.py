"""A call that must return (or raise) in time: a hang fails the test instead of stalling the suite."""
from __future__ import annotations

import subprocess
import threading
from typing import Any, Callable


def returns_within(seconds: float, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """``fn(*args, **kwargs)`` on a thread: its result, its exception re-raised here, or a test
    failure if it has not returned within ``seconds``."""
    box: dict[str, Any] = {}

    def run() -> None:
        try:
            box["value"] = fn(*args, **kwargs)
        except BaseException as exc:  # handed back to the test
            box["error"] = exc

    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(seconds)
    assert not t.is_alive(), f"{getattr(fn, '__name__', fn)} did not return within {seconds} s"
    if "error" in box:
        raise box["error"]
    return box.get("value")


def terminated(proc: subprocess.Popen, seconds: float = 30.0) -> int:
    """SIGTERM ``proc`` and its exit status; a test failure (with what it wrote to stderr, if
    piped) if it has not exited within ``seconds``, after which it is killed, never left
    running behind the suite."""
    proc.terminate()
    try:
        return proc.wait(timeout=seconds)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        err = proc.stderr.read() if proc.stderr is not None else ""
        raise AssertionError(f"{proc.args} did not exit within {seconds} s of SIGTERM: {err}") from None
