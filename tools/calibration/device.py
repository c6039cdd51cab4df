"""Device mode of ``stereocam calibrate URL --out DIR``: calibrate a camera on the line and store it.

Steps: switch the camera to raw (unrectified) free-run images (``rectify`` = 0, which the camera
advertises with INFO capability RAW_OUTPUT) while the operator or a fixture presents the board
(against the simulator: ``--scene board`` or ``sim://?scene=board``); feed the pairs to the solver
(tools/calibration/solve.py) until it has enough distinct views; gate; on a pass,
write the calibration to the device, read it back and compare byte for byte, and only then report
success. On any failure before the write nothing is written; a write that fails is followed by a
read-back (after reconnecting, when the link dropped: an unplug after the commit ran leaves the
new record stored), and the verdict says what the camera holds: the new calibration, its previous
one, or that it could not be read. The camera's own configuration is restored afterwards.
"""
from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

import stereocam
from stereocam.calibration_io import id_text
from stereocam.protocol import messages as m
from stereocam.tools.calibration.solve import BoardNotFoundError, CalibrationError, CalibrationResult, \
    GateFailedError, Progress, SolveConfig, calibrate_pairs
from stereocam.tools.exit_codes import EXIT_GATE, EXIT_NO_SOLUTION, EXIT_OK, EXIT_UNSUPPORTED, EXIT_WRITE



def raw_pairs(cam: stereocam.Camera, count: int, timeout: float
              ) -> Iterator[tuple[np.ndarray | None, np.ndarray | None]]:
    """Up to ``count`` raw (left, right) pairs from the running stream (None: a plane the frame lacks)."""
    for _ in range(count):
        f = cam.get_frame(timeout=timeout)
        if f.rectified:
            raise stereocam.ProtocolError("the camera sent rectified frames in raw mode")
        yield f.left, f.right


NO_BOARD_WARN_EVERY = 20
"""Captures in a row without the board in both images after which the operator is told (2 s at 10 fps)."""
NO_BOARD_GIVE_UP = 100
"""Captures without the board ever seen in both images after which the run ends (BoardNotFoundError)."""


class BoardWatch:
    """Wraps the solver's progress: says so when the board has not been seen in both images for
    NO_BOARD_WARN_EVERY captures, and ends the run when it was never seen in NO_BOARD_GIVE_UP."""

    def __init__(self, inner: Callable[[Progress], None] | None, fps: float,
                 warn: Callable[[str], None] = lambda text: print(text, file=sys.stderr, flush=True)):
        self.inner, self.fps, self.warn = inner, fps, warn
        self.captures = self.missed = self.seen = 0

    def __call__(self, p: Progress) -> None:
        if self.inner is not None:
            self.inner(p)
        self.captures += 1
        if p.view.status == "dropped" or p.view.status == "no_board":
            self.missed += 1
        else:
            self.missed, self.seen = 0, self.seen + 1
        if not self.seen and self.captures >= NO_BOARD_GIVE_UP:
            raise BoardNotFoundError(f"the board was not seen in both images in the first {self.captures} "
                                     "captures: put it in view of both cameras, or check --board")
        if self.missed and self.missed % NO_BOARD_WARN_EVERY == 0:
            self.warn(f"warning: no board in both images in the last {self.missed} captures "
                      f"({self.missed / self.fps:.0f} s): is it in view of both cameras?")


def calibrate_device(cam: stereocam.Camera, board, config: SolveConfig, outdir: Path, *, target: str = "user",
                     pairs: int = 200, fps: int = 10, size: tuple[int, int] | None = None, progress=None,
                     write_outputs=None, frame_timeout: float = 60.0, reconnect_timeout: float = 10.0
                     ) -> tuple[int, CalibrationResult | None, str]:
    """Returns (exit code, result or None, one-line verdict)."""
    info = cam.info()
    if not info.capabilities & m.Capability.RAW_OUTPUT:
        return (EXIT_UNSUPPORTED, None, f"{info.model} {info.serial} does not advertise raw output (INFO "
                "capability RAW_OUTPUT); it cannot be calibrated in device mode; nothing was written to the camera")
    before = cam.config()
    width, height = size or (info.sensor_width, info.sensor_height)
    setup = dict(rectify=0, width=width, height=height, fps=fps, trigger_mode=int(stereocam.TriggerMode.FREE_RUN))
    cam.configure(**setup)
    try:
        cam.start()
        try:
            result = calibrate_pairs(raw_pairs(cam, pairs, frame_timeout), board, config,
                                     progress=BoardWatch(progress, fps))
        finally:
            cam.stop()
    except GateFailedError as exc:
        return EXIT_GATE, None, "calibration FAILED the gate: " + "; ".join(exc.failures) + "; nothing was written to the camera"
    except CalibrationError as exc:
        return EXIT_NO_SOLUTION, None, f"{exc}; nothing was written to the camera"
    finally:
        cam.configure(**{k: before[k] for k in setup})
    if not result.passed:
        verdict = "calibration FAILED the gate: " + "; ".join(result.failures) + "; nothing was written to the camera"
        return _finish(EXIT_GATE, result, verdict, outdir, write_outputs)
    previous = cam.read_calibration(target)
    try:
        stored = cam.write_calibration(result.calibration, target)
    except stereocam.StereoCamError as exc:
        code, verdict = _after_failed_write(cam, result, target, previous, exc, reconnect_timeout)
        return _finish(code, result, verdict, outdir, write_outputs)
    result.quality = dataclasses.replace(result.quality, written=True, verified=True)
    verdict = (f"calibration PASSED, written to {cam.info().serial} as the {stored.source} record "
               f"(generation {stored.generation}, id {id_text(stored.calibration_id)}) and verified by read-back")
    return _finish(EXIT_OK, result, verdict, outdir, write_outputs)


def _after_failed_write(cam: stereocam.Camera, result: CalibrationResult, target: str,
                        previous: stereocam.StoredCalibration | None, exc: stereocam.StereoCamError,
                        reconnect_timeout: float) -> tuple[int, str]:
    """Read back what the camera holds after a write that raised ``exc`` (reconnecting first if the
    link dropped); the exit code and the verdict that says so (``result.quality`` updated)."""
    body = result.calibration.to_bytes()
    result.quality = dataclasses.replace(result.quality, written=False, verified=False)
    try:
        if isinstance(exc, stereocam.DisconnectedError):
            cam.reconnect(timeout=reconnect_timeout)
        held = cam.read_calibration(target)
        in_force = cam.info().calibration_id
    except stereocam.StereoCamError as again:
        return EXIT_WRITE, (f"writing the calibration failed: {exc}; the camera could not be read back after "
                            f"it ({again}): whether it holds the new calibration or its previous one is unknown")
    if held is not None and held.body == body:
        result.quality = dataclasses.replace(result.quality, written=True, verified=True)
        how = "after reconnecting, " if isinstance(exc, stereocam.DisconnectedError) else ""
        return EXIT_OK, (f"calibration PASSED; the write reported {type(exc).__name__} ({exc}), but {how}the camera "
                         f"holds it as the {held.source} record (generation {held.generation}, id "
                         f"{id_text(held.calibration_id)}), verified by read-back")
    if (held.body if held else None) == (previous.body if previous else None):
        kept = "the camera keeps its previous calibration"
    else:
        kept = "the camera holds neither the new nor its previous calibration"
    return EXIT_WRITE, f"writing the calibration failed: {exc}; {kept} (in force: {id_text(in_force)})"


def _finish(code: int, result: CalibrationResult, verdict: str, outdir: Path, write_outputs
            ) -> tuple[int, CalibrationResult, str]:
    if write_outputs is not None:
        write_outputs(result, outdir)
    return code, result, verdict
