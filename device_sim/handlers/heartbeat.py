"""HEARTBEAT → STATUS and TIME_SYNC → TIME (SPEC §4.7, §4.8), and the watchdog that stops a
stream and then drops the link when the host goes silent (§9)."""
from __future__ import annotations

import collections

from stereocam.protocol import messages as m

from ..clock import UnitClock
from ..link_layer.device_link import DeviceLink
from ..link_layer.dispatcher import Handler
from ..pipeline.capture_engine import CaptureEngine
from .config_store import ConfigStore


class HeartbeatHandlers:
    def __init__(self, clock: UnitClock, store: ConfigStore, engine: CaptureEngine, link: DeviceLink,
                 counters: collections.Counter[str]):
        self._clock = clock
        self._store = store
        self._engine = engine
        self._link = link
        self._counters = counters

    def handlers(self) -> dict[int, Handler]:
        return {m.MsgType.HEARTBEAT: self.heartbeat, m.MsgType.TIME_SYNC: self.time_sync}

    def heartbeat(self, _: m.Message) -> m.Status:
        return m.Status(self._clock.uptime_us(), self._engine.streaming, self._store.snapshot()["trigger_mode"],
                        self.status_counters())

    def time_sync(self, _: m.Message) -> m.Time:
        return m.Time(self._clock.now_us())

    def status_counters(self) -> dict[str, int]:
        st = self._link.stats
        c = dict(self._counters)
        c.update(frames_captured=self._engine.captured, frames_dropped=self._engine.dropped,
                 rx_bytes=st.bytes_in, rx_packets=st.packets, rx_garbage_bytes=st.garbage_bytes,
                 rx_header_crc_errors=st.header_crc_errors + st.bad_headers,
                 rx_payload_crc_errors=st.payload_crc_errors, rx_oversize=st.oversize,
                 rx_unsupported_version=st.unsupported_version, rx_message_timeouts=st.message_timeouts)
        return c

    def watchdog(self) -> None:
        """Called by the watchdog thread (SPEC §9): stop streaming once the host has been silent for
        the heartbeat timeout; drop the link once it has been silent for the link timeout."""
        timeout_ms = self._store.snapshot()["heartbeat_timeout_ms"]
        if self._engine.streaming and timeout_ms and self._link.silent_for() > timeout_ms / 1000:
            self._counters["heartbeat_timeouts"] += 1
            self._engine.stop()
        if self._link.drop_if_silent(timeout_ms):
            self._counters["links_dropped"] += 1

    def yield_link(self) -> bool:
        """Another host wants the unit (a TCP client knocking): drop the link if it is silent past
        its link timeout, the default one when the watchdog is off (SPEC §9). True if dropped."""
        dropped = self._link.drop_if_silent(self._store.snapshot()["heartbeat_timeout_ms"], contested=True)
        if dropped:
            self._counters["links_dropped"] += 1
        return dropped
