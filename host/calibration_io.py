"""Reading and writing the calibration stored on the device (protocol SPEC §12).

A write stages the body in chunks, commits it with its length and CRC-32, then reads the record
back and compares it byte for byte: success is only reported for what the device really holds.
"""
from __future__ import annotations

import zlib
from dataclasses import dataclass

from stereocam.protocol import messages as m
from stereocam.protocol.calibration import StereoCalibration
from stereocam.protocol.errors import ConfigError, ProtocolError, VerificationError

SOURCES = {"active": m.CalibSource.ACTIVE, "factory": m.CalibSource.FACTORY, "user": m.CalibSource.USER}


@dataclass(frozen=True)
class StoredCalibration:
    """A calibration record as the device holds it."""

    calibration: StereoCalibration
    body: bytes
    source: str  # "factory" or "user"
    generation: int
    calibration_id: int  # what frames carry while this record is in force


def id_text(calibration_id: int) -> str:
    """A calibration id as every tool prints it: 8 hex digits (JSON carries the number)."""
    return f"{calibration_id:08x}"


def read_calibration(request, source: str = "active") -> StoredCalibration | None:
    """The stored record (``active``: the one in force), or None if there is none."""
    if not isinstance(source, str) or source not in SOURCES:
        raise ConfigError(f"source must be one of {sorted(SOURCES)}, got {source!r}")
    body = b""
    while True:
        r = request(m.CalibRead(SOURCES[source], len(body), m.MAX_CALIB_CHUNK))
        if r.source == m.CalibSource.ACTIVE:
            return None
        if r.offset != len(body):
            raise ProtocolError(f"CALIB_DATA at offset {r.offset}, expected {len(body)}")
        body += r.data
        if len(body) >= r.total or not r.data:
            break
    if len(body) != r.total or m.calib_id(body) != r.calibration_id:
        raise ProtocolError(f"calibration body of {len(body)} of {r.total} bytes does not match its id "
                            f"{r.calibration_id:08x}")
    return StoredCalibration(StereoCalibration.from_bytes(body), body,
                             "factory" if r.source == m.CalibSource.FACTORY else "user", r.generation,
                             r.calibration_id)


def write_calibration(request, calib: StereoCalibration, target: str = "user") -> StoredCalibration:
    """Store ``calib`` as the ``target`` record, read it back, compare; VerificationError if it differs."""
    if not isinstance(calib, StereoCalibration):
        raise ConfigError(f"calibration must be a StereoCalibration, got {type(calib).__name__}")
    if not isinstance(target, str) or target not in ("factory", "user"):
        raise ConfigError(f"target must be 'factory' or 'user', got {target!r}")
    body = calib.to_bytes()
    for off in range(0, len(body), m.MAX_CALIB_CHUNK):
        r = request(m.CalibWrite(off, len(body), body[off:off + m.MAX_CALIB_CHUNK]))
        if r.staged != min(off + m.MAX_CALIB_CHUNK, len(body)):
            raise ProtocolError(f"device staged {r.staged} bytes after the chunk at {off}")
    state = request(m.CalibCommit(SOURCES[target], len(body), zlib.crc32(body)))
    try:
        back = read_calibration(request, target)
    except ProtocolError as exc:
        raise VerificationError(f"the {target} calibration could not be read back intact: {exc}") from exc
    if back is None or back.body != body:
        raise VerificationError(f"the {target} calibration read back from the device differs from what was "
                                "written")
    if back.generation != state.generation or back.calibration_id != m.calib_id(body):
        raise VerificationError(f"read back generation {back.generation} / id {back.calibration_id:08x}, the "
                                f"commit reported {state.generation} / {state.calibration_id:08x}")
    return back


def restore_factory(request) -> StoredCalibration | None:
    """Invalidate the user record; returns the record now in force (the factory one, if any)."""
    request(m.CalibRestore())
    return read_calibration(request, "active")
