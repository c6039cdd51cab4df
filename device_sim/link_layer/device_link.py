"""The device end of the host link: bytes in through ``receive``, replies and capture messages out
through the sink a transport gives to ``attach``. Every transport (in-process, pty, TCP, USB)
drives this one object."""
from __future__ import annotations

import threading
import time
from typing import Callable

from stereocam.protocol.framing import DEVICE_MESSAGE_TIMEOUT, Decoder, DecoderStats

from .dispatcher import Dispatcher

Sink = Callable[[bytes], None]


class DeviceLink:
    """One host at a time. ``on_lost`` runs when the host goes (detach, or a sink that fails);
    ``on_attach`` when a new host comes (per-link state such as the frame-repair chunk size resets).
    A request whose bytes stop arriving is abandoned after DEVICE_MESSAGE_TIMEOUT (SPEC §3)."""

    def __init__(self, dispatcher: Dispatcher, on_lost: Callable[[], None],
                 on_attach: Callable[[], None] = lambda: None):
        self.decoder = Decoder(message_timeout=DEVICE_MESSAGE_TIMEOUT)
        self._on_attach = on_attach
        self.last_rx = time.monotonic()  # when the host last sent a whole frame (the watchdog's clock)
        self._dispatcher = dispatcher
        self._on_lost = on_lost
        self._sink: Sink | None = None
        self._sink_lock = threading.Lock()
        self._rx_lock = threading.Lock()

    @property
    def stats(self) -> DecoderStats:
        return self.decoder.stats

    @property
    def attached(self) -> bool:
        """Whether a host link (in-process pipe, pty, socket, USB) currently holds this unit."""
        return self._sink is not None

    def attach(self, sink: Sink) -> None:
        """Send all further output to ``sink`` (called from device threads; may block)."""
        with self._sink_lock:
            self._sink = sink
        with self._rx_lock:  # a new host: its request ids say nothing about the last one's
            self._dispatcher.cache.clear()
            self._on_attach()
            self.decoder = Decoder(stats=self.decoder.stats, message_timeout=DEVICE_MESSAGE_TIMEOUT)
        self.last_rx = time.monotonic()

    def detach(self) -> None:
        """The host link is gone: output is discarded."""
        with self._sink_lock:
            self._sink = None
        self._on_lost()

    def receive(self, data: bytes) -> None:
        """Bytes from the host; replies go to the sink before this returns."""
        with self._rx_lock:
            for packet in self.decoder.feed(data):
                self.last_rx = time.monotonic()
                wire = self._dispatcher.answer(packet)
                with self._sink_lock:
                    self._emit(wire)

    def send(self, wire: bytes, still_wanted: Callable[[], bool]) -> bool:
        """One unsolicited message, if ``still_wanted()`` when the sink is free. The sink is taken per
        message, so a reply waits for at most one message on a slow link. False: not sent."""
        with self._sink_lock:
            return still_wanted() and self._emit(wire)

    def close(self) -> None:
        with self._sink_lock:
            self._sink = None

    def _emit(self, wire: bytes) -> bool:
        """Write under ``_sink_lock``; a failing sink means the link is gone."""
        if self._sink is None:
            return False
        try:
            self._sink(wire)
            return True
        except OSError:
            self._sink = None
            self._on_lost()
            return False
