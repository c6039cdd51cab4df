"""``replay://FILE`` — a recording played back by a simulated unit in this process.

``replay://run.mcap`` (relative) or ``replay:///abs/run.mcap``; options: ``speed=recorded|fast``
(default recorded), ``loop=1``, ``start=N`` (first frame index). The unit is the recorded one
(model, serial, calibration, configuration); see ``stereocam.device_sim.replay``.
"""
from __future__ import annotations

from urllib.parse import parse_qs

from stereocam.protocol.errors import ConfigError

from .inprocess import InProcessTransport

OPTIONS = {"speed", "loop", "start"}


def parse(url: str) -> tuple[str, dict]:
    """The file and the ReplaySource options a ``replay://`` URL names."""
    rest = url.split("://", 1)[1]
    path, _, query = rest.partition("?")
    if not path:
        raise ConfigError(f"replay:// URL needs a file: replay://run.mcap, got {url!r}")
    q = {k: v[-1] for k, v in parse_qs(query).items()}
    unknown = set(q) - OPTIONS
    if unknown:
        raise ConfigError(f"replay:// URL: unknown option(s) {sorted(unknown)}; known: {', '.join(sorted(OPTIONS))}")
    if q.get("speed", "recorded") not in ("recorded", "fast"):
        raise ConfigError(f"replay:// URL: speed is 'recorded' or 'fast', got {q['speed']!r}")
    try:
        start = int(q.get("start", "0"))
    except ValueError as exc:
        raise ConfigError(f"replay:// URL: start must be a frame index, got {q['start']!r}") from exc
    return path, {"realtime": q.get("speed", "recorded") == "recorded", "loop": q.get("loop", "0") in ("1", "true"),
                  "start": start}


class ReplayTransport(InProcessTransport):
    """The link to a replaying unit: it also says when the recording has been played to its end."""

    def ended(self) -> str | None:
        source = self.sim.engine.source
        return source.path if source.finished else None


def open_transport(url: str, timeout: float) -> ReplayTransport:
    from ..firmware import SimulatedCamera
    from ..replay import ReplaySource

    path, options = parse(url)
    return ReplayTransport(SimulatedCamera(source=ReplaySource(path, **options)), url)
