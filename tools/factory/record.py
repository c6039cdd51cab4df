"""Turning one run of ``stereocam calibrate`` into a factory database row."""
from __future__ import annotations

import dataclasses
import datetime as dt
from pathlib import Path

import stereocam
from stereocam.tools.calibration.solve import CalibrationResult
from stereocam.tools.factory.db import Attempt


def now_utc() -> str:
    return dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds").replace("+00:00", "Z")


def make_attempt(*, serial: str, started_at: str, station: str, mode: str, board: str,
                 result: CalibrationResult | None, passed: bool, reason: str, output_dir: Path,
                 blob: bytes | None) -> Attempt:
    """Every metric of `result` (if any) plus the verdict; `blob` is the body as written (None if not)."""
    a = Attempt(unit_serial=serial, started_at=started_at, station=station, tool_version=stereocam.__version__,
                mode=mode, board=board, passed=passed, reason=reason, output_dir=str(output_dir.resolve()),
                calibration=blob)
    if result is None:
        return a
    q, c = result.quality, result.calibration
    for key in ("rms_left", "rms_right", "rms_stereo", "epipolar_rms_px", "epipolar_all_rms_px", "views_used",
                "views_dropped", "written", "verified"):
        setattr(a, key, getattr(q, key))
    a.lens_model, a.fx_left, a.baseline_m = c.lens_model, float(c.K_left[0, 0]), c.baseline_m
    a.metrics = {**{k: v for k, v in dataclasses.asdict(q).items() if v is not None},
                 "lens_model_scores": result.model_scores, "failures": result.failures,
                 "dropped": {v.label: v.reason for v in result.dropped},
                 "fy_left": float(c.K_left[1, 1]), "fx_right": float(c.K_right[0, 0]),
                 "image_size": list(c.image_size)}
    return a
