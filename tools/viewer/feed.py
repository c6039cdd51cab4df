"""What both viewer sessions share: a daemon thread that takes the next item from a camera or a
group until closed, shows a camera error on the page and tries again."""
from __future__ import annotations

import abc
import threading
from typing import Any

import stereocam

RETRY_S = 0.5  # after a camera error, before the next try


class Feed(abc.ABC):
    """Subclasses implement ``_fetch`` (wait briefly for the next item; CameraTimeoutError when none
    came) and ``_take`` (keep it); ``error`` is the last camera error, None once items flow again."""

    def _start(self, name: str) -> None:
        self.error: str | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    @abc.abstractmethod
    def _fetch(self) -> Any:
        """The next item, waiting briefly; CameraTimeoutError when none came."""

    @abc.abstractmethod
    def _take(self, item: Any) -> None:
        """Keep ``item`` for the page."""

    def _recover(self, exc: stereocam.StereoCamError) -> None:  # noqa: B027 - a hook, doing nothing by default
        """After a camera error, before the next try (a subclass may reconnect here)."""

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                item = self._fetch()
            except stereocam.CameraTimeoutError:
                continue
            except stereocam.StereoCamError as exc:
                self.error = str(exc)
                self._recover(exc)
                self._stop.wait(RETRY_S)
                continue
            self.error = None
            self._take(item)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
