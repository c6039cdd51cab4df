"""The connection to one unit, under the user API: link, heartbeat, clock map, reconnect, frame repair.

It owns the threads a camera needs (the link's reader, the heartbeat, and repair workers only
once the device has agreed to resend frame parts) and the host-side counters, which threads
increment under locks and ``counters()`` reads as one frozen snapshot. Frames it assembles go to
``on_frame`` (on the reader thread or a repair worker: it must not block).
"""
from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, replace
from typing import Callable

from stereocam.protocol import messages as m
from stereocam.protocol.errors import (ConfigError, DisconnectedError, StereoCamError, TransportError,
                                       VersionMismatchError)
from stereocam.protocol.framing import VERSION_MAJOR, DecoderStats
from stereocam.protocol.params import TriggerMode

from .arguments import count_arg, request_timeout_arg, retries_arg, timeout_arg
from .clock import ArrivalStamp, ClockMap, SyncSample
from .device_types import DeviceInfo, DeviceStatus
from .frame_repair import RepairWorker
from .frame_types import Frame
from .frames import AssemblyStats, FrameAssembler
from .link import Link, LinkStats
from .transports import Transport, open_transport, reopen_url

SYNC_SAMPLES = 8
SYNC_PERIOD = 1.0  # seconds between background time-sync bursts (the map needs them to follow drift)
SYNC_BURST = 3  # round trips per burst: one of them usually finds the link free of frame data
MIN_HEARTBEAT_INTERVAL = 0.01  # s: a faster heartbeat would only load the link
HEARTBEAT_INTERVAL = 0.5  # s: the default (Camera's heartbeat_interval)
REPAIR_TIMEOUT = 0.5  # s per FRAME_RESEND try at most
_log = logging.getLogger(__name__)

StatusHook = Callable[[DeviceStatus, float], None]


@dataclass(frozen=True)
class Counters:
    """Host-side counters at one moment: link, decoder, frame assembly and delivery."""

    link: LinkStats
    decoder: DecoderStats
    assembly: AssemblyStats
    queue_overflow: int = 0  # frames the get_frame queue discarded because the user did not keep up
    stream_restarts: int = 0  # streams the device stopped (watchdog) that the host restarted

    @property
    def frames_dropped(self) -> int:
        """Captures the user did not get whole (delivered flawed ones included)."""
        return self.assembly.dropped + self.queue_overflow

    def as_dict(self) -> dict[str, int]:
        """Every counter by name, flat (``Camera.stats``)."""
        out = self.decoder.as_dict()
        for part in (self.link, self.assembly):
            out.update({k: getattr(part, k) for k in part.__dataclass_fields__})
        out.update(queue_overflow=self.queue_overflow, stream_restarts=self.stream_restarts,
                   frames_dropped=self.frames_dropped)
        return out


class Connection:
    """A live link to one unit, kept identified, clock-mapped and (on ``reconnect``) brought back."""

    def __init__(self, transport: Transport, on_frame: Callable[[Frame], None], on_status: StatusHook, *,
                 timeout: float, retries: int, heartbeat_interval: float, deliver_incomplete: bool):
        """``on_status(status, asked_at)`` gets every heartbeat's STATUS and when it was asked for."""
        self.url = transport.url
        try:
            self.timeout = request_timeout_arg(timeout)
            self._retries = retries_arg(retries)
            self._heartbeat_interval = timeout_arg(heartbeat_interval, "heartbeat_interval", MIN_HEARTBEAT_INTERVAL)
        except ConfigError:
            transport.close()  # the caller handed it over: nothing else will close it
            raise
        self._on_status = on_status
        self.clock = ClockMap()
        self.assembler = FrameAssembler(self.clock, on_frame, deliver_incomplete)
        self.last_status: DeviceStatus | None = None
        self._repairer: RepairWorker | None = None
        self._closed = threading.Event()
        self._last_sync = 0.0
        try:
            self._connect(transport)
        except BaseException:
            if self._repairer is not None:
                self._repairer.close()
            raise
        self._heartbeat = threading.Thread(target=self._heartbeat_loop, name="stereocam-heartbeat", daemon=True)

    def ended(self) -> str | None:
        """The recording this link's device has played to its end (Transport.ended), else None."""
        return self._arrivals.ended()

    def start_heartbeat(self) -> None:
        """Begin the periodic STATUS (to ``on_status``) and clock-sync bursts, once the owner is ready."""
        self._heartbeat.start()

    def _connect(self, transport: Transport) -> None:
        """Bring up a link on ``transport``: identify, stop any stale stream, map the clock."""
        self._arrivals = ArrivalStamp(transport)
        self.link = Link(self._arrivals, timeout=self.timeout, retries=self._retries,
                         on_event=self.assembler.on_message)
        try:
            self.info = self.fetch_info()
            self.assembler.set_limits(self.info.max_width, self.info.max_height)
            self._set_up_repair(transport)
            self.request(m.Stop())  # a known state: no stale stream from a previous session
            self.clock.reset()  # the unit may have rebooted: its clock starts over
            self.sync_clock(SYNC_SAMPLES)
        except BaseException:
            self.link.close()
            raise

    def _set_up_repair(self, transport: Transport) -> None:
        """Protocol 1.2 (SPEC §13): ask for this transport's chunk size and let the assembler request
        resends of damaged parts; with an older device frames travel and drop as in 1.1, and no
        repair worker is started."""
        self.assembler.repair = None
        if not self.info.capabilities & m.Capability.FRAME_REPAIR:
            return
        self.request(m.SetFrameLink(transport.frame_chunk or 0))
        if self._repairer is None:
            self._repairer = RepairWorker(lambda msg: self.link.request(msg, min(self.timeout, REPAIR_TIMEOUT), 2),
                                          self.assembler.on_resent, lambda exc: self.link.fail(exc))
        self.assembler.repair = self._repairer.submit

    @property
    def repairing(self) -> bool:
        """Whether frame repair was negotiated with the unit (its workers run)."""
        return self.assembler.repair is not None

    # -- requests -----------------------------------------------------------------------------
    def request(self, msg: m.Message, timeout: float | None = None) -> m.Message:
        return self.link.request(msg, timeout)

    def fetch_info(self) -> DeviceInfo:
        """INFO, read now; VersionMismatchError for a device of another major protocol version."""
        r = self.request(m.GetInfo())
        assert isinstance(r, m.Info)
        if r.protocol_version[0] != VERSION_MAJOR:
            raise VersionMismatchError(f"device speaks protocol {r.protocol_version[0]}.{r.protocol_version[1]}, "
                                       f"this host speaks {VERSION_MAJOR}.x")
        return DeviceInfo.from_message(r)

    def refresh_info(self) -> DeviceInfo:
        """Read INFO again (the calibration id changes when a calibration is written) and keep it."""
        self.info = self.fetch_info()
        return self.info

    def status(self) -> DeviceStatus:
        r = self.request(m.Heartbeat())
        assert isinstance(r, m.Status)
        return DeviceStatus(r.uptime_us, r.streaming, TriggerMode(r.trigger_mode), r.counters)

    def sync_clock(self, samples: int = 1) -> None:
        """Take ``samples`` time-sync round trips into the device→host clock map."""
        for _ in range(count_arg(samples, "samples", 1)):
            t0 = time.monotonic()
            r = self.request(m.TimeSync())
            t1 = time.monotonic()
            t1 = self._arrivals.last if t0 < self._arrivals.last < t1 else t1  # when the reply came in
            assert isinstance(r, m.Time)
            self.clock.add(SyncSample(t0, r.device_time_us, t1))
        self._last_sync = time.monotonic()

    def _heartbeat_loop(self) -> None:
        while not self._closed.wait(self._heartbeat_interval):
            try:
                asked_at = time.monotonic()
                self.last_status = self.status()
                self._on_status(self.last_status, asked_at)
                if time.monotonic() - self._last_sync > SYNC_PERIOD:
                    self.sync_clock(SYNC_BURST)
            except StereoCamError:
                pass  # a dead link shows in the user's next call; reconnect() brings a new one
            except Exception as exc:
                self.link.fail(exc)

    # -- state --------------------------------------------------------------------------------
    @property
    def alive(self) -> bool:
        """Whether the link is up (not closed, not failed)."""
        return self.link.alive

    @property
    def closed(self) -> bool:
        return self._closed.is_set()

    def check_alive(self) -> None:
        """Raise the link's error (DisconnectedError, ...) if it is down."""
        self.link.check_alive()

    def counters(self) -> Counters:
        """A consistent snapshot of the link's, the decoder's and the assembler's counters."""
        return Counters(self.link.stats, replace(self.link.decoder.stats), self.assembler.snapshot())

    # -- reconnect and close ------------------------------------------------------------------
    def reconnect(self, timeout: float = 10.0, backoff: float = 0.1, expected: bool = False) -> None:
        """After a disconnect: open the same unit again (by serial), retrying with exponential backoff
        until ``timeout``; DisconnectedError if it does not come back in time. ``expected``: a reset the
        caller asked for (logged at INFO instead of WARNING)."""
        timeout, backoff = timeout_arg(timeout), timeout_arg(backoff, "backoff")
        if self._closed.is_set():
            raise TransportError(f"{self.url}: camera closed; open it again with stereocam.open")
        serial = self.info.serial
        url = reopen_url(self.url, serial)
        deadline = time.monotonic() + timeout
        if self.link.alive:  # asked for while the link is up: nothing was lost
            _log.info("%s: reconnecting to serial %s via %s (the link was up)", self.url, serial, url)
        else:
            _log.log(logging.INFO if expected else logging.WARNING, "%s: link lost (%s); reconnecting to serial %s "
                     "via %s", self.url, self.link.error, serial, url)
        self.link.close()
        while True:
            try:
                self._connect(open_transport(url, self.timeout))
                if self.info.serial != serial:
                    self.link.close()
                    raise TransportError(f"{url} is serial {self.info.serial}, not {serial}")
                return
            except StereoCamError as exc:
                if time.monotonic() + backoff > deadline:
                    raise DisconnectedError(f"camera {serial} did not come back within {timeout:.3g} s: {exc}") \
                        from exc
                time.sleep(backoff)
                backoff = min(backoff * 2, 1.0)

    def close(self) -> None:
        """Stop the stream if the link is up, end the heartbeat, the link and the repair workers."""
        if self._closed.is_set():
            return
        self._closed.set()
        if self.link.alive:
            try:
                self.request(m.Stop(), timeout=0.5)
            except StereoCamError:
                pass
        if self._heartbeat.is_alive():
            self._heartbeat.join(timeout=2)
        self.link.close()  # first: a resend request in flight then fails at once
        if self._repairer is not None:
            self._repairer.close()
