"""``stereocam calibrate``: factory stereo calibration, from a camera or from image pairs.

    stereocam calibrate URL --out OUTDIR [--target user|factory]          (device mode)
    stereocam calibrate --images DIR --board 9x6 --square-size 0.025 --out OUTDIR   (offline)

Device mode (tools/calibrate_device.py) captures raw pairs of the calibration board, solves, gates,
writes the result to the camera, reads it back and compares it byte for byte before it reports
success; calibration.json then says written/verified true. The operator or a fixture presents the
board; the tool sends only protocol parameters (SPEC §5). Against a simulator, serve it showing its
board (``python -m stereocam.device_sim --scene board`` or ``sim://?scene=board``); its board is 9x6
inner corners of 30 mm, the device-mode default.

DIR holds pairs named left<N>.<ext> / right<N>.<ext> (any text between the side and the number,
e.g. left_003.png ↔ right3.png); they are paired by the integer N. The engine and the metric
definitions are in tools/calib_solve.py.

Outputs in OUTDIR:
  calibration.json   geometry + rms_left, rms_right, rms_stereo, epipolar_rms_px, views_used,
                     passed, written, verified (written/verified are false in offline mode)
  calibration.yaml   OpenCV FileStorage: K1 D1 K2 D2 R T R1 R2 P1 P2 Q + metrics   (only if passed)
  left.yaml, right.yaml   ROS camera_info (plumb_bob)                              (only if passed)
  report.png         per-view errors, coverage, rectified pair with epipolar lines
Exit status: 0 passed; 1 the camera could not be reached; 2 bad arguments or unreadable images;
3 no solution (board never found, too few views); 4 the solution failed the gate (calibration.json
says passed: false, the YAML files are not written and stale ones from an earlier run are removed);
5 the write to the camera failed or read back different (the camera keeps its previous calibration);
6 the camera does not advertise raw output (INFO capability RAW_OUTPUT).
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from stereocam.device_sim.calibration.board import BoardSpec
from stereocam.tools.calib_report import write_report
from stereocam.tools.calib_solve import PARAM_NAMES, CalibrationError, CalibrationResult, Progress, SolveConfig, calibrate_pairs

EXIT_OK, EXIT_USAGE, EXIT_NO_SOLUTION, EXIT_GATE = 0, 2, 3, 4
_NAME = re.compile(r"^(left|right)\D*?(\d+)\.(png|jpe?g|bmp|pgm|ppm|tiff?)$", re.IGNORECASE)
_PASS_ONLY = ("calibration.yaml", "left.yaml", "right.yaml")


def find_pairs(directory: Path) -> list[tuple[int, Path, Path]]:
    """(number, left path, right path) for every number that has both images, sorted by number."""
    if not directory.is_dir():
        raise ValueError(f"{directory} is not a directory")
    sides: dict[str, dict[int, Path]] = {"left": {}, "right": {}}
    for path in sorted(directory.iterdir()):
        m = _NAME.match(path.name)
        if m:
            side, number = m.group(1).lower(), int(m.group(2))
            if number in sides[side]:
                raise ValueError(f"two {side} images with number {number}: {sides[side][number].name}, {path.name}")
            sides[side][number] = path
    common = sorted(set(sides["left"]) & set(sides["right"]))
    if not common:
        raise ValueError(f"no left<N>/right<N> image pairs in {directory}")
    return [(n, sides["left"][n], sides["right"][n]) for n in common]


def _load(pairs: list[tuple[int, Path, Path]]) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    for _, left, right in pairs:
        images = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in (left, right)]
        for p, img in zip((left, right), images):
            if img is None:
                raise ValueError(f"cannot read image {p}")
        yield images[0], images[1]


def _bar(value: float, width: int = 10) -> str:
    n = int(round(value * width))
    return "#" * n + "-" * (width - n)


def print_progress(p: Progress) -> None:
    """One line per pair: its fate, the kept/held-out counts and the coverage bars."""
    bars = " ".join(f"{name} [{_bar(c)}]" for name, c in zip(PARAM_NAMES, p.coverage))
    print(f"{p.view.label:<24} {p.view.status:<9} kept {p.kept:>2} held-out {p.held_out:>2}  {bars}", flush=True)


def _mat(a: np.ndarray) -> dict[str, object]:
    a = np.atleast_2d(a)
    return {"rows": a.shape[0], "cols": a.shape[1], "data": [float(v) for v in a.ravel()]}


def ros_camera_info(name: str, size: tuple[int, int], K: np.ndarray, D: np.ndarray,
                    R: np.ndarray, P: np.ndarray) -> str:
    """A ROS camera_info YAML document (camera_calibration_parsers layout)."""
    lines = [f"image_width: {size[0]}", f"image_height: {size[1]}", f"camera_name: {name}"]
    for key, value in (("camera_matrix", K), ("distortion_model", None), ("distortion_coefficients", D),
                       ("rectification_matrix", R), ("projection_matrix", P)):
        if value is None:
            lines.append("distortion_model: plumb_bob")
            continue
        m = _mat(value)
        lines += [f"{key}:", f"  rows: {m['rows']}", f"  cols: {m['cols']}",
                  "  data: [" + ", ".join(repr(v) for v in m["data"]) + "]"]
    return "\n".join(lines) + "\n"


def write_outputs(result: CalibrationResult, outdir: Path) -> list[Path]:
    """Write the files listed in the module docstring; returns the paths written."""
    outdir.mkdir(parents=True, exist_ok=True)
    c, q, r = result.calibration, result.quality, result.rectification
    written = [outdir / "calibration.json", outdir / "report.png"]
    written[0].write_text(json.dumps(c.to_json_dict(q), indent=2) + "\n")
    write_report(result, written[1])
    if not result.passed:
        for name in _PASS_ONLY:
            (outdir / name).unlink(missing_ok=True)
        return written
    fs = cv2.FileStorage(str(outdir / "calibration.yaml"), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", c.image_size[0])
    fs.write("image_height", c.image_size[1])
    for key, value in (("K1", c.K_left), ("D1", c.D_left.reshape(1, 5)), ("K2", c.K_right),
                       ("D2", c.D_right.reshape(1, 5)), ("R", c.R), ("T", c.T.reshape(3, 1)), ("R1", r.R1),
                       ("R2", r.R2), ("P1", r.P1), ("P2", r.P2), ("Q", r.Q)):
        fs.write(key, np.asarray(value, dtype=np.float64))
    for key in ("rms_left", "rms_right", "rms_stereo", "epipolar_rms_px"):
        fs.write(key, float(getattr(q, key)))
    fs.release()
    (outdir / "left.yaml").write_text(ros_camera_info("left", c.image_size, c.K_left, c.D_left, r.R1, r.P1))
    (outdir / "right.yaml").write_text(ros_camera_info("right", c.image_size, c.K_right, c.D_right, r.R2, r.P2))
    return written + [outdir / n for n in _PASS_ONLY]


def _board(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"(\d+)[xX](\d+)", text)
    if not m:
        raise argparse.ArgumentTypeError(f"board must be COLSxROWS inner corners, e.g. 9x6, got {text!r}")
    return int(m.group(1)), int(m.group(2))


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="stereocam calibrate", description=__doc__.splitlines()[0])
    ap.add_argument("url", nargs="?", help="camera to calibrate (device mode)")
    ap.add_argument("--images", type=Path, help="folder of left<N>/right<N> images (offline mode)")
    ap.add_argument("--board", type=_board, default=(9, 6), help="inner corners COLSxROWS (default 9x6)")
    ap.add_argument("--square-size", type=float, default=None,
                    help="square side in metres (required offline; device default 0.03)")
    ap.add_argument("--out", type=Path, required=True, help="output folder")
    ap.add_argument("--target", choices=["user", "factory"], default="user", help="device record to write")
    ap.add_argument("--pairs", type=int, default=200, help="device mode: most pairs to capture")
    ap.add_argument("--size", type=_board, default=None, metavar="WxH",
                    help="device mode: capture format (default the full sensor)")
    d = SolveConfig()
    ap.add_argument("--max-stereo-rms", type=float, default=d.max_stereo_rms_px, help="gate, px")
    ap.add_argument("--max-epipolar", type=float, default=d.max_epipolar_rms_px, help="gate, px (held-out)")
    ap.add_argument("--min-views", type=int, default=d.min_views, help="distinct views needed to solve")
    ap.add_argument("--max-views", type=int, default=d.max_views, help="stop after this many kept views")
    ap.add_argument("--holdout-every", type=int, default=d.holdout_every,
                    help="hold out every N-th pair with a board for the epipolar check")
    ap.add_argument("-q", "--quiet", action="store_true", help="no per-pair progress lines")
    return ap


def _fail(code: int, text: str) -> int:
    print(f"stereocam calibrate: error: {text}", file=sys.stderr)
    return code


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if (args.url is None) == (args.images is None):
        return _fail(EXIT_USAGE, "give a camera URL (device mode) or --images DIR (offline), not both")
    if args.square_size is None:
        if args.images is not None:
            return _fail(EXIT_USAGE, "--square-size is required with --images")
        args.square_size = 0.03
    if not 0 < args.square_size <= 1.0:
        return _fail(EXIT_USAGE, f"--square-size is in metres (0 < s <= 1), got {args.square_size}")
    if args.holdout_every < 2 or args.min_views < 3:
        return _fail(EXIT_USAGE, "--holdout-every must be >= 2 and --min-views >= 3")
    config = SolveConfig(args.max_stereo_rms, args.max_epipolar, args.min_views, args.max_views, args.holdout_every)
    if args.url is not None:
        return _device_mode(args, config)
    try:
        board = BoardSpec(*args.board, args.square_size)
        pairs = find_pairs(args.images)
        labels = [f"{l.name}|{r.name}" for _, l, r in pairs]
        result = calibrate_pairs(_load(pairs), board, config, labels, None if args.quiet else print_progress)
    except CalibrationError as exc:
        return _fail(EXIT_NO_SOLUTION, f"{exc} (nothing written)")
    except ValueError as exc:
        return _fail(EXIT_USAGE, str(exc))
    paths = write_outputs(result, args.out)
    q = result.quality
    print(f"rms left {q.rms_left:.3f} px  right {q.rms_right:.3f} px  stereo {q.rms_stereo:.3f} px  "
          f"held-out epipolar {q.epipolar_rms_px:.3f} px  views {q.views_used}  baseline "
          f"{result.calibration.baseline_m * 1000:.2f} mm")
    print("wrote " + ", ".join(str(p) for p in paths))
    if not result.passed:
        return _fail(EXIT_GATE, "calibration FAILED the gate: " + "; ".join(result.failures))
    print("calibration PASSED")
    return EXIT_OK


def _device_mode(args: argparse.Namespace, config: SolveConfig) -> int:
    import stereocam
    from stereocam.tools.calibrate_device import calibrate_device

    try:
        with stereocam.open(args.url, timeout=2.0) as cam:
            code, result, verdict = calibrate_device(
                cam, BoardSpec(*args.board, args.square_size), config, args.out, target=args.target,
                pairs=args.pairs, size=args.size, write_outputs=write_outputs,
                progress=None if args.quiet else print_progress)
    except stereocam.StereoCamError as exc:
        return _fail(1, f"camera {args.url}: {exc}")
    if result is not None:
        q = result.quality
        print(f"rms left {q.rms_left:.3f} px  right {q.rms_right:.3f} px  stereo {q.rms_stereo:.3f} px  "
              f"held-out epipolar {q.epipolar_rms_px:.3f} px  views {q.views_used}")
    if code:
        return _fail(code, verdict)
    print(verdict)
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
