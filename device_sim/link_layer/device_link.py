"""The device end of the host link: bytes in through ``receive``, replies and capture messages out
through the sink a transport gives to ``attach``. Every transport (in-process, pty, TCP, USB)
drives this one object."""
from __future__ import annotations

import threading
import time
from typing import Callable

from stereocam.protocol.framing import DEVICE_MESSAGE_TIMEOUT, Decoder, DecoderStats

from ..clock import REAL_CLOCK, Clock
from .dispatcher import Dispatcher

Sink = Callable[[bytes], None]
HangUp = Callable[[], None]

FIRST_MESSAGE_TIMEOUT_S = 3.0
"""A new link must deliver its first frame within this (the default heartbeat timeout, SPEC §9),
whatever heartbeat_timeout_ms an earlier host left configured."""
LINK_TIMEOUT_FACTOR = 2
"""A link that has spoken is dropped after this many heartbeat timeouts of silence (SPEC §9): the
watchdog stops the stream at one, so a host whose traffic comes back in time can restart it."""


CONTESTED_LINK_TIMEOUT_S = LINK_TIMEOUT_FACTOR * FIRST_MESSAGE_TIMEOUT_S
"""With the watchdog off (heartbeat_timeout_ms = 0) a link silent this long (the default link
timeout) yields to another host that wants the unit (SPEC §9)."""


def link_timeout(spoken: bool, heartbeat_timeout_ms: int, contested: bool = False) -> float | None:
    """Seconds of silence after which a link is dropped; None: never (heartbeat_timeout_ms = 0 and
    no other host waiting: ``contested``)."""
    if not spoken:
        return FIRST_MESSAGE_TIMEOUT_S
    if heartbeat_timeout_ms:
        return LINK_TIMEOUT_FACTOR * heartbeat_timeout_ms / 1000
    return CONTESTED_LINK_TIMEOUT_S if contested else None


class DeviceLink:
    """One host at a time. ``on_lost`` runs when the host goes (detach, drop, or a sink that fails);
    ``on_attach`` when a new host comes (per-link state such as the frame-repair chunk size resets).
    A request whose bytes stop arriving is abandoned after DEVICE_MESSAGE_TIMEOUT (SPEC §3).
    ``timebase``: the clock the silence is measured on."""

    def __init__(self, dispatcher: Dispatcher, on_lost: Callable[[], None],
                 on_attach: Callable[[], None] = lambda: None, timebase: Clock = REAL_CLOCK):
        self.decoder = Decoder(message_timeout=DEVICE_MESSAGE_TIMEOUT)
        self._on_attach = on_attach
        self._timebase = timebase
        self.last_rx = timebase.monotonic()  # when the host last sent a whole frame (the watchdog's clock)
        self.spoken = False  # whether this link delivered a frame since it was attached
        self.drops = 0  # links dropped for silence
        self._dispatcher = dispatcher
        self._on_lost = on_lost
        self._sink: Sink | None = None
        self._hang_up: HangUp | None = None
        self._sink_lock = threading.Lock()
        self._rx_lock = threading.Lock()

    @property
    def stats(self) -> DecoderStats:
        return self.decoder.stats

    @property
    def attached(self) -> bool:
        """Whether a host link (in-process pipe, pty, socket, USB) currently holds this unit."""
        return self._sink is not None

    def attach(self, sink: Sink, hang_up: HangUp | None = None) -> None:
        """Send all further output to ``sink`` (called from device threads; may block).
        ``hang_up``: how the transport ends this link when it is dropped (close the socket...); it
        must also make a blocked ``sink`` call fail, and must not block."""
        with self._sink_lock:
            self._sink, self._hang_up = sink, hang_up
        with self._rx_lock:  # a new host: its request ids say nothing about the last one's
            self._dispatcher.cache.clear()
            self._on_attach()
            self.decoder = Decoder(stats=self.decoder.stats, message_timeout=DEVICE_MESSAGE_TIMEOUT)
            self.spoken = False
        self.last_rx = self._timebase.monotonic()

    def detach(self) -> None:
        """The host link is gone: output is discarded."""
        with self._sink_lock:
            self._sink = None
        self._on_lost()

    def silent_for(self) -> float:
        """Seconds since the host last sent a whole frame (or since it attached). While the decoder
        waits for the rest of a frame whose header arrived, the host is not silent; once that wait
        is over, silence counts from its end (SPEC §9: a stray header never costs a host its link)."""
        silent = self._timebase.monotonic() - self.last_rx
        since, limit = self.decoder.waiting_since, self.decoder.message_timeout
        if since is not None and limit is not None:
            silent = min(silent, max(time.monotonic() - (since + limit), 0.0))
        return silent

    def drop_if_silent(self, heartbeat_timeout_ms: int, contested: bool = False) -> bool:
        """SPEC §9: end a link silent for longer than its link timeout (from the watchdog thread,
        never blocked by a sender stuck in the sink; ``contested``: another host is waiting for the
        unit). True if it was dropped."""
        limit = link_timeout(self.spoken, heartbeat_timeout_ms, contested)
        if self._sink is None or limit is None or self.silent_for() <= limit:
            return False
        hang_up = self._hang_up
        self._sink, self._hang_up = None, None  # no lock: a sender may hold it, blocked in the sink
        self.drops += 1
        self._on_lost()
        if hang_up is not None:
            hang_up()
        return True

    def receive(self, data: bytes) -> None:
        """Bytes from the host; replies go to the sink before this returns."""
        with self._rx_lock:
            abandoned = self.decoder.stats.message_timeouts
            packets = self.decoder.feed(data)
            if self.decoder.stats.message_timeouts != abandoned:  # a wait just ended: silence starts now
                self.last_rx = self._timebase.monotonic()
            for packet in packets:
                self.last_rx = self._timebase.monotonic()
                self.spoken = True
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
            self._sink, self._hang_up = None, None

    def _emit(self, wire: bytes) -> bool:
        """Write under ``_sink_lock``; a failing sink means the link is gone."""
        if self._sink is None:
            return False
        sink = self._sink
        try:
            sink(wire)
            return True
        except OSError:
            if self._sink is sink:
                self._sink, self._hang_up = None, None
            self._on_lost()
            return False
