"""The firmware's calibration subsystem and its requests (SPEC §12): flash records, staged
writes, rectification maps; CALIB_READ, CALIB_WRITE, CALIB_COMMIT, CALIB_RESTORE.

At boot and after every successful write it loads the record in force (user, else factory) and
builds the rectification maps for the current output format from it. A refused or failed write
raises Refusal (the dispatcher's NACK) and leaves the calibration in force unchanged.
"""
from __future__ import annotations

import threading
import zlib
from pathlib import Path

from stereocam.protocol import messages as m
from stereocam.protocol.calibration import CalibrationFormatError, StereoCalibration
from stereocam.protocol.calibration_limits import PlausibilityLimits
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.rectification import EQUIDISTANT_FOV_DEG

from ..calibration.acceptance import usable_calibration
from ..calibration.flash import FlashError, NorFlash
from ..calibration.rectify import RectificationMaps, rectification_maps
from ..calibration.store import CalibrationStore, StoreError, StoredRecord
from ..link_layer.dispatcher import Handler
from ..link_layer.refusal import Refusal

MAX_BODY = 4096


class CalibrationService:
    def __init__(self, flash: str | Path | NorFlash, truth: StereoCalibration, factory_calibrated: bool,
                 limits: PlausibilityLimits | None = None):
        """``limits``: what this rig can physically have (default: the protocol's wide limits for a
        sensor of the true calibration's size)."""
        self.limits = limits or PlausibilityLimits(sensor_size=truth.image_size)
        self.flash = flash if isinstance(flash, NorFlash) else NorFlash(flash)
        self.store = CalibrationStore(self.flash)
        if factory_calibrated and self.store.read_factory() is None and not self.store.factory_locked:
            # what the factory line did to this unit before it shipped
            self.store.write_factory(truth.to_bytes())
            self.store.lock_factory()
        self._staging = bytearray()
        self._staging_total = 0
        self._maps: dict[tuple[int, int, int | None], RectificationMaps] = {}
        self._lock = threading.Lock()  # the capture thread reads what requests change
        self.record: StoredRecord | None = None
        self.calibration: StereoCalibration | None = None
        self.rejected_records = 0  # valid CRC but a body this firmware cannot use (malformed or implausible)
        self._load()

    def reload(self) -> None:
        """Boot: read the calibration in force from flash again."""
        self._load()

    # -- state in force -------------------------------------------------------------------------
    def _load(self) -> None:
        """Put the newest usable record in force: user if valid and parseable, else factory."""
        record, calibration = None, None
        seen: set[tuple[str, int]] = set()
        for rec in (self.store.read(), self.store.read_factory()):
            if rec is None or (rec.region, rec.slot) in seen:
                continue
            seen.add((rec.region, rec.slot))
            try:
                calibration = usable_calibration(rec.body, self.limits)
                record = rec
                break
            except CalibrationFormatError:
                self.rejected_records += 1
        with self._lock:
            self._maps.clear()
            self.record, self.calibration = record, calibration

    @property
    def calibration_id(self) -> int:
        return m.calib_id(self.record.body) if self.record else 0

    def maps(self, width: int, height: int, fov_deg: int = int(EQUIDISTANT_FOV_DEG)
             ) -> tuple[RectificationMaps | None, int]:
        """Rectification maps for this output format and rectified field of view (``rectified_fov``:
        equidistant lenses only) from the calibration in force (cached: the maps of one field of view
        at a time), and that calibration's id — one consistent pair even while a write is being committed."""
        with self._lock:
            record, calibration = self.record, self.calibration  # set together (or neither)
            if record is None or calibration is None:
                return None, 0
            fov = fov_deg if calibration.lens_model == "equidistant" else None
            key = (width, height, fov)
            if key not in self._maps:
                self._maps = {k: v for k, v in self._maps.items() if k[2] == fov}
                self._maps[key] = rectification_maps(calibration.scaled(width, height), fov or EQUIDISTANT_FOV_DEG)
            return self._maps[key], m.calib_id(record.body)

    def _state(self, cls: type[m.CalibState]) -> m.CalibState:
        rec = self.record
        source = {None: m.CalibSource.ACTIVE, "factory": m.CalibSource.FACTORY, "user": m.CalibSource.USER}[
            rec.region if rec else None]
        return cls(source, rec.generation if rec else 0, self.calibration_id)

    # -- requests -------------------------------------------------------------------------------
    def handlers(self) -> dict[int, Handler]:
        return {m.MsgType.CALIB_READ: self.read, m.MsgType.CALIB_WRITE: self.write,
                m.MsgType.CALIB_COMMIT: self.commit, m.MsgType.CALIB_RESTORE: lambda _: self.restore_factory()}

    def read(self, msg: m.CalibRead) -> m.CalibData:
        if msg.source == m.CalibSource.ACTIVE:
            rec = self.record  # the one in force (a stored but unusable record is not)
        elif msg.source == m.CalibSource.FACTORY:
            rec = self.store.read_factory()
        elif msg.source == m.CalibSource.USER:
            rec = self.store.read()
            rec = rec if rec is not None and rec.region == "user" else None
        else:
            raise Refusal(ErrorCode.OUT_OF_RANGE, f"unknown calibration source {msg.source}")
        if rec is None:
            return m.CalibData(m.CalibSource.ACTIVE, 0, 0, 0, msg.offset, b"")
        source = m.CalibSource.FACTORY if rec.region == "factory" else m.CalibSource.USER
        chunk = rec.body[msg.offset:msg.offset + min(msg.length, m.MAX_CALIB_CHUNK)]
        return m.CalibData(source, rec.generation, m.calib_id(rec.body), len(rec.body), msg.offset, chunk)

    def write(self, msg: m.CalibWrite) -> m.CalibWritten:
        if not 0 < msg.total <= MAX_BODY:
            raise Refusal(ErrorCode.OUT_OF_RANGE, f"calibration body of {msg.total} bytes; limit {MAX_BODY}")
        if msg.offset == 0:
            self._staging, self._staging_total = bytearray(), msg.total
        if msg.total != self._staging_total or msg.offset != len(self._staging):
            raise Refusal(ErrorCode.BAD_STATE, f"chunk at {msg.offset} of {msg.total} does not continue the "
                              f"staged {len(self._staging)} of {self._staging_total} bytes; restart at offset 0")
        if msg.offset + len(msg.data) > msg.total:
            raise Refusal(ErrorCode.OUT_OF_RANGE, f"chunk runs past the announced {msg.total} bytes")
        self._staging += msg.data
        return m.CalibWritten(len(self._staging))

    def commit(self, msg: m.CalibCommit) -> m.CalibState:
        if msg.target not in (m.CalibSource.FACTORY, m.CalibSource.USER):
            raise Refusal(ErrorCode.OUT_OF_RANGE, f"commit target must be factory (1) or user (2), not {msg.target}")
        if msg.target == m.CalibSource.FACTORY and self.store.factory_locked:
            raise Refusal(ErrorCode.BAD_STATE, "the factory calibration is write-protected; write target=user")
        body, announced = bytes(self._staging), self._staging_total
        self._staging, self._staging_total = bytearray(), 0  # one commit attempt per staging
        if len(body) != announced or not body:
            raise Refusal(ErrorCode.BAD_PAYLOAD, f"the staging is incomplete: {len(body)} of the {announced} bytes "
                              "its CALIB_WRITEs announced; nothing written")
        if msg.total != len(body) or zlib.crc32(body) != msg.crc:
            raise Refusal(ErrorCode.BAD_PAYLOAD, f"staged {len(body)} bytes with CRC {zlib.crc32(body):08x}, "
                              f"commit announced {msg.total} bytes with CRC {msg.crc:08x}; nothing written")
        try:
            usable_calibration(body, self.limits)
        except CalibrationFormatError as exc:
            raise Refusal(ErrorCode.BAD_PAYLOAD, f"not a calibration this firmware can use: {exc}; "
                          "nothing written") from exc
        try:
            if msg.target == m.CalibSource.FACTORY:
                written = self.store.write_factory(body)
            else:
                written = self.store.write_user(body)
        except (FlashError, StoreError) as exc:
            self._load()  # whatever survived on flash is what is in force
            raise Refusal(ErrorCode.STORAGE, f"flash write failed ({exc}); the previous calibration "
                              "is still in force") from exc
        if msg.target == m.CalibSource.FACTORY:
            try:
                self.store.lock_factory()
            except FlashError as exc:
                self._load()
                raise Refusal(ErrorCode.STORAGE, f"the factory record was written but write-protecting it "
                                  f"failed ({exc}); it is stored unprotected") from exc
        self._load()
        stored = self.store.read_factory() if msg.target == m.CalibSource.FACTORY else self.record
        if stored is None or stored.body != body or stored.generation != written.generation:
            raise Refusal(ErrorCode.STORAGE, "the record read back from flash differs from what was written")
        return self._state(m.CalibCommitted)

    def restore_factory(self) -> m.CalibState:
        if self.store.read_factory() is None:
            raise Refusal(ErrorCode.BAD_STATE, "no factory calibration stored; nothing to restore")
        try:
            self.store.restore_factory()
        except (FlashError, StoreError) as exc:
            self._load()
            raise Refusal(ErrorCode.STORAGE, f"flash write failed ({exc})") from exc
        self._load()
        return self._state(m.CalibRestored)
