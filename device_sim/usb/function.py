"""What a firmware must offer to be plugged into the simulated bus."""
from __future__ import annotations

from typing import Callable, Protocol


class UsbFunction(Protocol):
    """What a firmware must offer to be plugged into the simulated bus."""

    def attach(self, sink: Callable[[bytes], None], hang_up: Callable[[], None] | None = None) -> None: ...

    @property
    def attached(self) -> bool: ...

    def detach(self) -> None: ...

    def receive(self, data: bytes) -> None: ...
