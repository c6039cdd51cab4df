"""Tiny byte-level firmwares for exercising the USB path without the camera firmware.

They implement the same three methods as ``device_sim.SimulatedCamera`` (``attach``,
``detach``, ``receive``) and are what the USB tests and ``tools/bench/usb.py`` plug in.
"""
from __future__ import annotations

import threading
from typing import Callable

Sink = Callable[[bytes], None]


class EchoDevice:
    """Sends every received chunk straight back as one IN transfer."""

    model = "Echo"
    firmware_version = "1.2.3"

    def __init__(self, serial: str = "ECHO0001") -> None:
        self.serial = serial
        self.received: list[bytes] = []
        self._sink: Sink | None = None

    def attach(self, sink: Sink, hang_up: Callable[[], None] | None = None) -> None:  # never drops
        self._sink = sink

    @property
    def attached(self) -> bool:
        return self._sink is not None

    def detach(self) -> None:
        self._sink = None

    def receive(self, data: bytes) -> None:
        self.received.append(bytes(data))
        sink = self._sink
        if sink is not None:
            sink(data)

    def send(self, data: bytes) -> None:
        """Device-initiated IN transfer (as firmware streaming a frame would)."""
        if self._sink is None:
            raise BrokenPipeError("not attached")
        self._sink(data)


class SourceDevice:
    """Streams bytes on request: receiving ASCII ``"<count>"`` makes a firmware thread send
    ``count`` bytes as IN transfers of ``chunk`` bytes (the last one possibly shorter)."""

    model = "Source"
    firmware_version = "1.0.0"

    def __init__(self, serial: str = "SRC0001", chunk: int = 640 * 480 * 2) -> None:
        self.serial = serial
        self.chunk = chunk
        self.error: OSError | None = None
        self._sink: Sink | None = None
        self._threads: list[threading.Thread] = []
        self._block = bytes(range(256)) * (chunk // 256 + 1)

    def attach(self, sink: Sink, hang_up: Callable[[], None] | None = None) -> None:  # never drops
        self._sink = sink

    @property
    def attached(self) -> bool:
        return self._sink is not None

    def detach(self) -> None:
        self._sink = None
        for thread in self._threads:
            thread.join(2.0)

    def receive(self, data: bytes) -> None:
        count = int(bytes(data).decode("ascii"))
        thread = threading.Thread(target=self._stream, args=(count,), daemon=True)
        self._threads.append(thread)
        thread.start()

    def _stream(self, count: int) -> None:
        sink = self._sink
        try:
            while count > 0 and sink is not None:
                n = min(count, self.chunk)
                sink(self._block[:n])
                count -= n
        except OSError as exc:  # unplugged mid-stream (BrokenPipeError): stop quietly
            self.error = exc
