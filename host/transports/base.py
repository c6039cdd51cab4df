"""The one interface every transport implements: a bidirectional byte pipe."""
from __future__ import annotations

from abc import ABC, abstractmethod


class Transport(ABC):
    """A byte pipe to one device. The link layer (host/link.py) does everything else.

    ``read`` returns whatever bytes are available (at most ``max_bytes``), waiting up to
    ``timeout`` seconds for the first one; it returns ``b""`` on timeout and raises
    ``DisconnectedError`` when the device is gone. ``write`` sends all of ``data`` or raises.
    """

    url: str = ""
    frame_chunk: int | None = None  # FRAME_DATA bytes per message this link wants (None: device default)

    @abstractmethod
    def write(self, data: bytes) -> None:
        """Send all bytes."""

    @abstractmethod
    def read(self, max_bytes: int, timeout: float) -> bytes:
        """Up to ``max_bytes`` available bytes; ``b""`` after ``timeout`` seconds with none."""

    def ended(self) -> str | None:
        """The file whose end the device behind this link has reached (a ``replay://`` recording played
        once to its end): it will send no more frames. None for a camera (a live source never ends)."""
        return None

    @abstractmethod
    def close(self) -> None:
        """Release the link; idempotent."""

    def __enter__(self) -> "Transport":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
