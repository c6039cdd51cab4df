"""``stereocam calibrate``: factory stereo calibration, from a camera or from image pairs.

    stereocam calibrate URL --out OUTDIR [--target user|factory]          (device mode)
    stereocam calibrate --images DIR --board 9x6 --square-size 0.025 --out OUTDIR   (offline)
    stereocam calibrate --images DIR --board charuco:19x26:0.005:0.004:DICT_4X4_250 --out OUTDIR
    stereocam calibrate --images DIR --board aprilgrid:6x6:0.088:0.3 --out OUTDIR   (or --board target.yaml)

Device mode (tools/calibration/device.py) captures raw pairs of the calibration board, solves, gates,
writes the result to the camera, reads it back and compares it byte for byte before it reports
success; calibration.json then says written/verified true. The operator or a fixture presents the
board; the tool sends only protocol parameters (SPEC §5). Against a simulator, serve it showing its
board (``python -m stereocam.device_sim --scene board`` or ``sim://?scene=board``); its board is 9x6
inner corners of 30 mm, the device-mode default.

DIR holds the pairs as left01.png / right01.png, left_003.png ↔ right3.png, L01.png / R01.png,
cam_left-7.jpg / cam_right-7.jpg, or in two folders (left/ right/, cam0/ cam1/, ...); they are
paired by the number in the name (tools/calibration/files.py). An unreadable image or a pair of another
size is dropped with its reason. Offline, every pair with the
board in both images is used except the outliers by their own residuals, which are listed with the
reason; the lens model is chosen on held-out pairs unless --lens-model names one. The engine and
the metric definitions are in tools/calibration/solve.py and tools/calibration/fit.py; boards in
tools/calibration/boards.py.

Outputs in OUTDIR:
  calibration.json   geometry + lens_model + rms_left, rms_right, rms_stereo, epipolar_rms_px,
                     epipolar_all_rms_px, views_used, views_dropped, passed, written, verified
                     (written/verified are false in offline mode), dropped (file and reason),
                     lens_model_scores (held-out score per model tried), lens_model_failures (why a
                     model failed), unsynchronised_pairs (pairs whose left and right frames are not
                     from the same instant, with the evidence: tools/calibration/sync.py; also printed)
  calibration.yaml   OpenCV FileStorage: lens_model K1 D1 K2 D2 R T R1 R2 P1 P2 Q + metrics  (if passed)
  left.yaml, right.yaml   ROS camera_info (plumb_bob, rational_polynomial or equidistant) (if passed)
  camchain.yaml      Kalibr camchain (cam0 left, cam1 right, T_cn_cnm1; equidistant or radtan): for the
                     equidistant model and a plumb_bob one whose k3 is negligible  (if passed)
  camera_info/left_WxH.yaml, right_WxH.yaml   device mode: camera_info for every stream size the
                     unit offers (tools/calibration/camera_info.py)                              (if passed)
  report.png         per-view errors named by file (worst views called out), coverage, rectified pair
  report.html        the same as tables: every pair's fate and errors, the lens models tried
Exit status: 0 passed; 1 the camera could not be reached; 2 bad arguments or unreadable images;
3 no solution (board never found, too few views); 4 the solution failed the gate (calibration.json
says passed: false, the YAML files are not written and stale ones from an earlier run are removed);
5 the write to the camera failed or read back different (the verdict says what the camera holds);
6 the outputs could not be saved (in device mode after a successful write: the camera holds the new
calibration and the factory record says so). --out and --db are checked before anything is
captured or written; every attempt is recorded in the factory database (tools/factory/).
7 the camera does not advertise raw output (INFO capability RAW_OUTPUT): nothing was written.
"""
from __future__ import annotations

import math
import socket
import sys
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import click
import cv2
import numpy as np

from stereocam.tools.calibration.board_text import parse_board
from stereocam.tools.calibration.boards import describe
from stereocam.tools.calibration.camera_info import stream_sizes
from stereocam.tools.calibration.files import find_pairs
from stereocam.tools.calibration.fit import OutlierRules
from stereocam.tools.calibration.lens import ALIASES
from stereocam.tools.calibration.outputs import (
    PairProgress,
    print_summary,
    write_outputs,
)
from stereocam.tools.calibration.solve import (
    CalibrationError,
    CalibrationResult,
    GateFailedError,
    SolveConfig,
    UnusableImagesError,
    calibrate_pairs,
)
from stereocam.tools.camera.session import writable_dir
from stereocam.tools.exit_codes import EXIT_GATE, EXIT_NO_SOLUTION, EXIT_OK, EXIT_SAVE, EXIT_USAGE
from stereocam.tools.factory.cli import db_url
from stereocam.tools.factory.db import GATE_FAILED, FactoryDB, FactoryDBError, default_url
from stereocam.tools.factory.record import make_attempt, now_utc
from stereocam.tools.options import CONTEXT, SIZE, Finite, epilog



def _load(pairs: list[tuple[int, Path, Path]]) -> Iterator[tuple[np.ndarray | None, np.ndarray | None]]:
    """The pairs' images; None for a file OpenCV cannot read (the pair is dropped, named)."""
    for _, left, right in pairs:
        yield cv2.imread(str(left), cv2.IMREAD_GRAYSCALE), cv2.imread(str(right), cv2.IMREAD_GRAYSCALE)


class Range(click.ParamType):
    """``MIN:MAX`` as (min, max)."""

    name = "MIN:MAX"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> tuple[float, float]:
        if isinstance(value, tuple):
            return value
        try:
            lo, hi = (float(v) for v in str(value).split(":"))
        except ValueError:
            self.fail(f"expected MIN:MAX, got {value!r}", param, ctx)
        if not (math.isfinite(lo) and math.isfinite(hi)):
            self.fail(f"MIN and MAX must be finite numbers, got {value!r}", param, ctx)
        return lo, hi


_DOC = __doc__.replace("``", "")
_D, _O = SolveConfig(), OutlierRules()


@click.command("calibrate", context_settings=CONTEXT,
               epilog=epilog("Calibrate's own exit codes: " + _DOC[_DOC.index("Exit status:") + len("Exit status:"):].strip()))
@click.argument("url", required=False)
@click.option("--images", type=click.Path(path_type=Path), default=None,
              help="Folder of left<N>/right<N> (or L<N>/R<N>) images, or of left/ and right/ folders (offline mode).")
@click.option("--board", default="9x6", show_default=True,
              help="COLSxROWS inner corners of a chessboard, charuco:COLSxROWS:SQUARE:MARKER:DICT, "
                   "aprilgrid:COLSxROWS:TAG_SIZE:SPACING_RATIO (Kalibr) or a Kalibr target .yaml "
                   "(squares; lengths in metres).")
@click.option("--square-size", type=float, default=None,
              help="Chessboard square side in metres (required offline).  [default: 0.03 in device mode]")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), required=True, help="Output folder.")
@click.option("--target", type=click.Choice(["user", "factory"]), default="user", show_default=True,
              help="Device record to write: user (any unit), or factory (only a unit fresh from assembly: once "
                   "written the factory record is write-protected and the unit refuses, exit 5).")
@click.option("--pairs", type=click.IntRange(min=1), default=200, show_default=True,
              help="Device mode: most pairs to capture.")
@click.option("--size", type=SIZE, default=None, help="Device mode: capture format.  [default: the full sensor]")
@click.option("--lens-model", type=click.Choice(["auto", *ALIASES]), default="auto", show_default=True,
              help="Lens model; auto: chosen by held-out error, the simpler wins ties.")
@click.option("--max-stereo-rms", type=Finite(min=0, min_open=True), default=_D.max_stereo_rms_px, show_default=True,
              help="Gate: stereo RMS, px.")
@click.option("--max-epipolar", type=Finite(min=0, min_open=True), default=_D.max_epipolar_rms_px, show_default=True,
              help="Gate: held-out epipolar RMS, px.")
@click.option("--max-pixel-aspect", type=Finite(min=1), default=_D.max_pixel_aspect, show_default=True,
              help="Gate: fy/fx must lie within [1/A, A].")
@click.option("--baseline-range", type=Range(), default=f"{_D.min_baseline_m}:{_D.max_baseline_m}", show_default=True,
              help="Gate: plausible baseline, metres.")
@click.option("--min-views", type=int, default=_D.min_views, show_default=True,
              help="Device mode: distinct views needed.")
@click.option("--max-views", type=click.IntRange(min=1), default=_D.max_views, show_default=True,
              help="Device mode: stop after this many views.")
@click.option("--min-pairs", type=int, default=_D.min_pairs, show_default=True,
              help="Offline: pairs with the board (outliers removed) needed.")
@click.option("--holdout-every", type=int, default=_D.holdout_every, show_default=True,
              help="Hold out every N-th pair for the lens-model choice and the epipolar check.")
@click.option("--model-tie", type=Finite(min=0), default=_D.model_tie, show_default=True,
              help="Relative held-out score difference within which the simpler lens model wins.")
@click.option("--outlier-k", type=Finite(min=0), default=_O.k, show_default=True,
              help="Outlier: > median + k x 1.4826 MAD ...")
@click.option("--outlier-ratio", type=Finite(min=0), default=_O.ratio, show_default=True, help="... and > ratio x median.")
@click.option("--outlier-rounds", type=click.IntRange(min=0), default=_O.rounds, show_default=True, help="Outlier removal rounds.")
@click.option("--max-drop-fraction", type=Finite(0, 1), default=_O.max_drop_fraction, show_default=True,
              help="Most pairs removed as outliers, fraction.")
@click.option("--db", default=default_url(), show_default=True, callback=db_url,
              help="Factory database for the record of this attempt: SQLite path or postgresql://...")
@click.option("--station", default=socket.gethostname(), show_default=True, help="Station name in the factory record.")
@click.option("--serial", default=None,
              help="Unit serial in the factory record.  [default: the camera's; offline the folder name]")
@click.option("-q", "--quiet", is_flag=True,
              help="No per-pair lines; only the progress bar (pairs done / total, rate) on a terminal.")
def command(**params: Any) -> int:
    """Factory stereo calibration, from a camera (URL: device mode; written to the unit and verified)
    or from image pairs (--images DIR: offline). DIR holds pairs paired by the number in the name
    (left01.png / right01.png, L01.png / R01.png, ...) or two folders (left/ right/, cam0/ cam1/).
    Writes calibration.json, calibration.yaml, left.yaml / right.yaml and report.png / report.html
    to --out, and records every attempt in the factory database (--db)."""
    return calibrate(SimpleNamespace(**params))


def _config(args: SimpleNamespace) -> SolveConfig:
    return SolveConfig(
        max_stereo_rms_px=args.max_stereo_rms, max_epipolar_rms_px=args.max_epipolar, min_views=args.min_views,
        max_views=args.max_views, min_pairs=args.min_pairs, holdout_every=args.holdout_every,
        lens_model=ALIASES.get(args.lens_model, "auto"), model_tie=args.model_tie,
        outliers=OutlierRules(args.outlier_k, args.outlier_ratio, args.outlier_rounds, args.max_drop_fraction),
        max_pixel_aspect=args.max_pixel_aspect, min_baseline_m=args.baseline_range[0],
        max_baseline_m=args.baseline_range[1])


def _fail(code: int, text: str) -> int:
    print(f"stereocam calibrate: error: {text}", file=sys.stderr)
    return code


def _record(db: FactoryDB, args: SimpleNamespace, serial: str, started: str, result: CalibrationResult | None,
            code: int, reason: str, blob: bytes | None) -> None:
    attempt = make_attempt(serial=serial, started_at=started, station=args.station,
                           mode="device" if args.url else "offline", board=describe(args.board), result=result,
                           passed=code == EXIT_OK or (code == EXIT_SAVE and result is not None and result.passed),
                           reason=reason, output_dir=args.out, blob=blob)
    try:
        row = db.record(attempt)
        print(f"factory record: attempt {row} in {db.url}")
    except FactoryDBError as exc:
        print(f"stereocam calibrate: warning: {exc}", file=sys.stderr)


def calibrate(args: SimpleNamespace) -> int:
    """Check the arguments, then calibrate in device or offline mode; returns the exit code."""
    started = now_utc()
    if args.url is None and args.images is None:
        return _fail(EXIT_USAGE, "nothing to calibrate: give a camera URL (device mode) or --images DIR (offline)")
    if args.url is not None and args.images is not None:
        return _fail(EXIT_USAGE, "give a camera URL (device mode) or --images DIR (offline), not both")
    board_sized = args.board.lower().startswith(("charuco:", "aprilgrid:")) or args.board.lower().endswith(
        (".yaml", ".yml"))  # the board text gives its own lengths
    if args.square_size is None and not board_sized:
        if args.images is not None:
            return _fail(EXIT_USAGE, "--square-size is required with --images and a chessboard")
        args.square_size = 0.03
    if args.square_size is not None and not 0 < args.square_size <= 1.0:
        return _fail(EXIT_USAGE, f"--square-size is in metres (0 < s <= 1), got {args.square_size}")
    if args.holdout_every < 2 or args.min_views < 3 or args.min_pairs < 4:
        return _fail(EXIT_USAGE, "--holdout-every must be >= 2, --min-views >= 3 and --min-pairs >= 4")
    if args.url is not None and args.max_views < args.min_views:  # device mode would never have enough views
        return _fail(EXIT_USAGE, f"--max-views ({args.max_views}) must be >= --min-views ({args.min_views})")
    if args.max_pixel_aspect < 1 or not 0 < args.baseline_range[0] < args.baseline_range[1]:
        return _fail(EXIT_USAGE, "--max-pixel-aspect must be >= 1 and --baseline-range 0 < MIN < MAX")
    try:
        args.board = parse_board(args.board, args.square_size)
        config = _config(args)
    except ValueError as exc:  # ConfigError too: a rule the engine cannot apply
        return _fail(EXIT_USAGE, str(exc))
    try:  # made and written to before anything is captured or written to a camera
        writable_dir(args.out, keep=False)
    except OSError as exc:
        return _fail(EXIT_USAGE, f"--out: {exc.strerror or exc}; nothing was done")
    try:
        db = FactoryDB(args.db)
    except FactoryDBError as exc:
        return _fail(EXIT_USAGE, f"{exc}; nothing was done")
    with db:
        if args.url is not None:
            return _device_mode(args, config, db, started)
        return _offline(args, config, db, started)


def _offline(args: SimpleNamespace, config: SolveConfig, db: FactoryDB, started: str) -> int:
    serial = args.serial or args.images.resolve().name
    try:
        pairs = find_pairs(args.images)
        labels = [f"{l.name}|{r.name}" for _, l, r in pairs]
        with PairProgress(len(pairs), args.quiet) as progress:
            result = calibrate_pairs(_load(pairs), args.board, config, labels, progress, select=False)
    except UnusableImagesError as exc:  # unreadable images: exit 2, as the help says
        _record(db, args, serial, started, None, EXIT_USAGE, str(exc), None)
        return _fail(EXIT_USAGE, f"{exc} (nothing written)")
    except GateFailedError as exc:  # fitted, but no fit can be stored: the gate's verdict, nothing to write
        reason = GATE_FAILED + "; ".join(exc.failures)
        _record(db, args, serial, started, None, EXIT_GATE, reason, None)
        return _fail(EXIT_GATE, f"{reason} (nothing written)")
    except CalibrationError as exc:
        _record(db, args, serial, started, None, EXIT_NO_SOLUTION, str(exc), None)
        return _fail(EXIT_NO_SOLUTION, f"{exc} (nothing written)")
    except ValueError as exc:
        return _fail(EXIT_USAGE, str(exc))
    code = EXIT_OK if result.passed else EXIT_GATE
    reason = "passed" if result.passed else GATE_FAILED + "; ".join(result.failures)
    try:
        paths = write_outputs(result, args.out)
    except OSError as exc:
        code, reason = EXIT_SAVE, f"saving the outputs failed: {exc}"
        paths = []
    print_summary(result)
    _record(db, args, serial, started, result, code, reason, None)
    if paths:
        print("wrote " + ", ".join(str(p) for p in paths))
    if code:
        return _fail(code, reason)
    print("calibration PASSED")
    return EXIT_OK


def _device_mode(args: SimpleNamespace, config: SolveConfig, db: FactoryDB, started: str) -> int:
    import stereocam
    from stereocam.tools.calibration.device import calibrate_device

    save_errors: list[OSError] = []

    def save(result: CalibrationResult, outdir: Path) -> None:
        try:
            write_outputs(result, outdir, sizes)
        except OSError as exc:  # the camera may already hold the new calibration: say so, keep the record
            save_errors.append(exc)

    serial = args.serial or args.url
    try:
        with stereocam.open(args.url, timeout=2.0) as cam:
            serial = args.serial or cam.info().serial
            sizes = stream_sizes((cam.info().sensor_width, cam.info().sensor_height))
            with PairProgress(args.pairs, args.quiet) as progress:
                code, result, verdict = calibrate_device(
                    cam, args.board, config, args.out, target=args.target,
                    pairs=args.pairs, size=args.size, write_outputs=save, progress=progress)
    except stereocam.StereoCamError as exc:
        _record(db, args, serial, started, None, 1, f"camera {args.url}: {exc}", None)
        return _fail(1, f"camera {args.url}: {exc}")
    if save_errors:
        verdict = f"{verdict}; but saving the outputs to {args.out} failed: {save_errors[0]}"
        code = code or EXIT_SAVE
    if result is not None:
        print_summary(result)
    blob = result.calibration.to_bytes() if result is not None and result.quality.written else None
    _record(db, args, serial, started, result, code, verdict, blob)
    if code:
        return _fail(code, verdict)
    print(verdict)
    return EXIT_OK

