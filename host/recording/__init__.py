"""Recording: captures of a unit to MCAP files in the ROS 2 profile, and reading them back.

``Camera.record(path, frames=N)`` or ``record(camera, path, ...)`` writes a file; ``Recorder`` is the
writer underneath (frames in, file out, on its own thread). Topics and message types: ``schemas``.
"""
from stereocam.protocol.extras import raise_missing

try:
    from .convert import LinkCounters
    from .recorder import DamagedRecordingError, Recorder, RecorderStats, RecordingError, UnitDescription
    from .session import Progress, RecordingListener, describe, record
except ModuleNotFoundError as exc:  # mcap, zstandard: pip install 'stereocam[recording]'
    raise_missing(exc, "recording")

__all__ = ["record", "describe", "Recorder", "RecorderStats", "RecordingError", "DamagedRecordingError",
           "UnitDescription", "LinkCounters", "Progress", "RecordingListener"]
