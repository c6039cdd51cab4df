"""A recording's metadata records, checked: what the file says about the unit (INFO, configuration,
calibration), its clock offset and its summary counters. A value that is not what it should be (a
damaged or hostile file) is a DamagedRecordingError naming the file, the record and the field."""
from __future__ import annotations

from pathlib import Path

from stereocam.calibration_io import StoredCalibration
from stereocam.protocol.calibration import StereoCalibration

from .convert import LinkCounters
from .recorder import CALIBRATION, CONFIG, DEVICE, RECORDING, SUMMARY, DamagedRecordingError  # noqa: F401 (DEVICE: for readers)

SUMMARY_COUNTS = ("frames", "camera_bytes", *LinkCounters.__dataclass_fields__)  # the summary's integer fields
Metadata = dict[str, dict[str, str]]


def _damaged(path: Path, record: str, key: str, why: str) -> DamagedRecordingError:
    return DamagedRecordingError(f"{path}: metadata {record} field {key!r} {why}; the file is damaged")


def integer(path: Path, record: str, key: str, value: object) -> int:
    """``value`` of field ``key`` of metadata ``record`` as an integer."""
    try:
        return int(str(value).strip(), 10)
    except ValueError as exc:
        raise _damaged(path, record, key, f"is {value!r}, not an integer") from exc


def config(path: Path, metadata: Metadata) -> dict[str, int]:
    """The recorded configuration, name -> integer."""
    return {k: integer(path, CONFIG, k, v) for k, v in metadata.get(CONFIG, {}).items()}


def calibration(path: Path, metadata: Metadata) -> StoredCalibration | None:
    """The recorded stored calibration, or None if the unit had none."""
    c = metadata.get(CALIBRATION)
    if c is None:
        return None
    missing = [k for k in ("body_hex", "source", "generation", "calibration_id") if k not in c]
    if missing:
        raise _damaged(path, CALIBRATION, missing[0], "is missing")
    try:
        body = bytes.fromhex(c["body_hex"])
    except ValueError as exc:
        raise _damaged(path, CALIBRATION, "body_hex", f"is not hexadecimal ({exc})") from exc
    try:
        parsed = StereoCalibration.from_bytes(body)
    except Exception as exc:  # any parse failure of a hostile body is damage
        raise _damaged(path, CALIBRATION, "body_hex", f"is not a calibration body ({exc})") from exc
    return StoredCalibration(parsed, body, c["source"], integer(path, CALIBRATION, "generation", c["generation"]),
                             integer(path, CALIBRATION, "calibration_id", c["calibration_id"]))


def clock_offset_ns(path: Path, metadata: Metadata) -> int:
    """Host wall clock minus monotonic clock while recording (0 if not recorded)."""
    return integer(path, RECORDING, "clock_offset_ns", metadata.get(RECORDING, {}).get("clock_offset_ns", 0))


def summary_counts(path: Path, metadata: Metadata) -> dict[str, int]:
    """The summary's counters that the file has (frames, camera bytes, drops by where they happened)."""
    s = metadata.get(SUMMARY, {})
    return {k: integer(path, SUMMARY, k, s[k]) for k in SUMMARY_COUNTS if k in s}
