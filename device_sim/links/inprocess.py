"""``sim://`` — a simulated camera in this process, joined by an in-memory byte pipe.

``sim://?seed=N`` makes a fresh unit (closed with the transport); ``sim://?seed=N&serial=S`` opens
the live unit S if this process has it free, else makes one with that seed and serial (never two
units with one serial); a bare ``sim://`` unit 0. ``sim://?serial=S`` (no seed) only opens the live,
unattached simulator with that serial in this process (``stereocam.list_devices`` lists them) and
raises TransportError when there is none: a serial that is not found never makes a new unit.
``scene=lab|wall|board`` sets what the unit looks at (a simulator setting, not a device parameter;
also applied to a live unit); ``lens=standard|wide|fisheye`` the lens class of a unit it makes
(rig/lens.py; a live unit keeps its lenses). ``line=NAME`` wires a new unit's trigger connector to
the in-process line NAME (``sim://?seed=11&line=L`` and ``sim://?seed=12&line=L`` are two heads on
one wire, ready for a ``CameraGroup``); without it a unit's connector is unplugged. Host writes go
straight into the firmware's ``receive``; the firmware's output lands in a bounded FIFO the host
reads (a full FIFO blocks the device, as a full USB or TCP buffer would).
"""
from __future__ import annotations

import threading
import weakref
from urllib.parse import parse_qs, urlsplit

from stereocam.protocol.errors import ConfigError, DisconnectedError, TransportError

from .. import registry
from ..rig.lens import LensClass
from ..rig.scene import Scene
from ..trigger import named_line

from stereocam.discovery import DeviceEntry
from stereocam.transports.base import Transport

FIFO_BYTES = 8 << 20


class ByteFifo:
    """Bounded byte FIFO between threads."""

    def __init__(self, capacity: int = FIFO_BYTES):
        self._buf = bytearray()
        self._cond = threading.Condition()
        self._capacity = capacity
        self.closed = False

    def put(self, data: bytes) -> None:
        with self._cond:
            while len(self._buf) >= self._capacity and not self.closed:
                self._cond.wait(0.1)
            if self.closed:
                raise BrokenPipeError("reader gone")
            self._buf += data
            self._cond.notify_all()

    def get(self, max_bytes: int, timeout: float) -> bytes:
        with self._cond:
            if not self._buf and not self.closed:
                self._cond.wait(timeout)
            out = bytes(self._buf[:max_bytes])
            del self._buf[:max_bytes]
            self._cond.notify_all()
            return out

    def close(self) -> None:
        with self._cond:
            self.closed = True
            self._cond.notify_all()


class InProcessTransport(Transport):
    """Byte pipe to a SimulatedCamera living in this process."""

    def __init__(self, sim, url: str = "sim://", owns: bool = True):
        self.sim = sim
        self.url = url
        self._owns = owns
        self._went_down = False
        self._fifo = ByteFifo()
        self._closed = False
        self._unsubscribe = sim.on_power(self._on_power)
        sim.attach(self._fifo.put, hang_up=self._fifo.close)  # dropped by the device: the host reads EOF

    def _gone(self) -> DisconnectedError:
        why = "is closed" if self._closed else "was dropped by the device (no request for the link timeout, SPEC §9)"
        return DisconnectedError(f"{self.url} {why}")

    def _on_power(self, event: str) -> None:
        """The unit went down (reboot, power cut): this link is gone; the host reconnects by serial."""
        if event == "down":
            self._went_down = True
            self._unsubscribe()
            self._fifo.close()

    def write(self, data: bytes) -> None:
        if self._fifo.closed:
            raise self._gone()
        self.sim.receive(data)

    def read(self, max_bytes: int, timeout: float) -> bytes:
        data = self._fifo.get(max_bytes, timeout)
        if not data and self._fifo.closed:
            raise self._gone()
        return data

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        dropped = self._fifo.closed  # the device dropped this link (SPEC §9): it may serve another by now
        self._fifo.close()
        self._unsubscribe()
        if not dropped:
            self.sim.detach()
        if self._owns and self._went_down:  # rebooting (an update, a power cycle): the unit lives on, and
            _handed_over.add(self.sim)      # the next link to it (the host reconnecting) takes it over
        elif self._owns and not (dropped and self.sim.attached):
            self.sim.close()


SEED_MAX = (1 << 32) - 1
_handed_over: "weakref.WeakSet[object]" = weakref.WeakSet()  # units whose owning link closed while they rebooted


def open_transport(url: str, timeout: float) -> InProcessTransport:
    query = parse_qs(urlsplit(url).query, keep_blank_values=True)
    unknown = set(query) - {"seed", "serial", "scene", "lens", "line"}
    if unknown:
        raise ConfigError(f"sim:// URL: unknown option(s) {sorted(unknown)}; known: seed, serial, scene, lens, line")
    if any(len(v) > 1 for v in query.values()):
        raise ConfigError(f"sim:// URL: an option given twice in {url!r}")
    text = query.get("seed", ["0"])[0]
    if not (text.isascii() and text.isdigit()) or int(text) > SEED_MAX:
        raise ConfigError(f"sim:// URL: seed must be an integer 0..{SEED_MAX}, got {text!r}")
    seed = int(text)
    scene = Scene.parse(query["scene"][0]) if "scene" in query else None
    lens = LensClass.parse(query["lens"][0]) if "lens" in query else LensClass.STANDARD
    serial = query.get("serial", [None])[0]
    line = named_line(query["line"][0]) if "line" in query else None
    live = registry.find_free(serial) if serial is not None else None
    if live is not None and not live.powered:
        raise DisconnectedError(f"simulated unit {serial} is off or rebooting")
    if live is not None:  # the unit with that serial is alive here: open it, never a second one
        if line is not None and live.trigger_line is not line:
            raise ConfigError(f"{url}: simulator {serial} is alive here on another trigger line; a live unit "
                              "is not rewired")
        if scene is not None:
            live.scene = scene
        owns = live in _handed_over  # a unit a closed link owned when it rebooted: this link owns it now
        _handed_over.discard(live)
        return InProcessTransport(live, url, owns=owns)
    if serial is not None and "seed" not in query:
        held = [s.serial for s in registry.live_simulators()]
        state = "in use by another host (a link in this process)" if serial in held else "not found"
        raise TransportError(f"{url}: simulator {serial!r} {state} in this process (free ones: "
                             f"{[e.serial for e in discover()] or 'none'}); "
                             f"sim://?seed=N&serial={serial} makes a new one")
    from ..firmware import SimulatedCamera

    return InProcessTransport(SimulatedCamera(serial=serial, seed=seed, scene=scene or Scene.LAB, lens=lens,
                                              trigger_line=line), url)


def discover() -> list[DeviceEntry]:
    """Simulators alive in this process and held by no link (``sim://?serial=SN`` opens one)."""
    return [DeviceEntry(f"sim://?serial={s.serial}", s.serial, s.model, "sim", s.firmware_version, simulated=True,
                        location="this process") for s in registry.live_simulators() if not s.attached]


def reopen_url(url: str, serial: str) -> str:
    """The same unit again: the live one with that serial if it is still here (after a reboot), else
    (a unit opened by seed closes with its link) the same seed and serial freshly booted."""
    query = parse_qs(urlsplit(url).query)
    if "seed" in query:
        extra = "".join(f"&{key}={query[key][0]}" for key in ("scene", "lens", "line") if key in query)
        return f"sim://?seed={query['seed'][0]}&serial={serial}{extra}"
    return f"sim://?serial={serial}"
