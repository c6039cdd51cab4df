"""What ``stereocam calibrate`` prints and writes: progress lines, the summary, the output files
(listed in tools/calibration/calibrate.py's docstring)."""
from __future__ import annotations

import json
import shutil
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from stereocam.tools.calibration.report import write_html, write_report
from stereocam.tools.calibration.coverage import PARAM_NAMES
from stereocam.tools.calibration.solve import CalibrationResult, Progress
from stereocam.tools.calibration.camera_info import kalibr_camchain, ros_camera_info, write_camera_info
from stereocam.tools.progress import progress_wanted

_PASS_ONLY = ("calibration.yaml", "left.yaml", "right.yaml", "camchain.yaml")


def _bar(value: float, width: int = 10) -> str:
    n = int(round(value * width))
    return "#" * n + "-" * (width - n)


def progress_line(p: Progress) -> str:
    """One pair: its fate, the kept/held-out counts and the coverage bars."""
    bars = " ".join(f"{name} [{_bar(c)}]" for name, c in zip(PARAM_NAMES, p.coverage))
    line = f"{p.view.label:<24} {p.view.status:<9} kept {p.kept:>2} held-out {p.held_out:>2}  {bars}"
    return line + (f"  ({p.view.reason})" if p.view.status == "dropped" and p.view.reason else "")


class PairProgress:
    """A bar with pairs done / total and the rate (tqdm, on stderr, on a terminal; elsewhere one line
    at the end), and a line per pair above it unless ``quiet``. Use as a context manager; call it
    with each Progress."""

    def __init__(self, total: int, quiet: bool = False):
        self._bar = tqdm(total=total, unit="pair", desc="calibration", file=sys.stderr,
                         disable=not progress_wanted())
        self._quiet = quiet
        self._total, self._done, self._t0 = total, 0, time.monotonic()

    def __call__(self, p: Progress) -> None:
        if not self._quiet:
            self._bar.write(progress_line(p), file=sys.stdout)
        self._bar.set_postfix(kept=p.kept, held_out=p.held_out, refresh=False)
        self._bar.update()
        self._done += 1

    def __enter__(self) -> "PairProgress":
        return self

    def __exit__(self, *exc: object) -> None:
        self._bar.close()
        if self._bar.disable:  # no bar in a log: the figures it would have ended on, once
            seconds = time.monotonic() - self._t0
            print(f"calibration: {self._done}/{self._total} pairs in {seconds:.1f} s "
                  f"({self._done / seconds if seconds else 0.0:.1f} pair/s)", file=sys.stderr)


def print_summary(result: CalibrationResult) -> None:
    """Dropped pairs with their reasons, the lens model choice and the metrics."""
    for v in result.dropped:
        print(f"dropped {v.label}: {v.reason}")
    q, c = result.quality, result.calibration
    scores = "  ".join(f"{m} {s:.3f}" for m, s in result.model_scores.items())
    print(f"lens model {c.lens_model} (held-out score px: {scores})")
    for model, why in result.model_failures.items():
        print(f"lens model {model} failed: {why}")
    note = result.sync.message() if result.sync is not None else None
    if note:
        print(f"warning: {note}")
    print(f"rms left {q.rms_left:.3f} px  right {q.rms_right:.3f} px  stereo {q.rms_stereo:.3f} px  "
          f"held-out epipolar {q.epipolar_rms_px:.3f} px  all-pairs epipolar {q.epipolar_all_rms_px:.3f} px  "
          f"pairs used {q.views_used} dropped {q.views_dropped}  fx {c.K_left[0, 0]:.2f} px  "
          f"baseline {c.baseline_m * 1000:.3f} mm")


def write_outputs(result: CalibrationResult, outdir: Path,
                  sizes: list[tuple[int, int]] | None = None) -> list[Path]:
    """Write the files listed in the module docstring (camera_info/ for `sizes`); returns the paths written."""
    outdir.mkdir(parents=True, exist_ok=True)
    c, q, r = result.calibration, result.quality, result.rectification
    written = [outdir / "calibration.json", outdir / "report.png", outdir / "report.html"]
    doc = c.to_json_dict(q)
    doc["dropped"] = [{"pair": v.label, "reason": v.reason} for v in result.dropped]
    doc["lens_model_scores"] = result.model_scores
    doc["lens_model_failures"] = result.model_failures
    if result.sync is not None:
        doc["unsynchronised_pairs"] = [
            {"pair": p.label, "epipolar_px": round(p.epipolar_px, 4), "stereo_px": round(p.stereo_px, 4),
             "reprojection_px": round(p.mono_px, 4), "board_motion_mm": round(p.motion_mm, 3),
             "board_motion_deg": round(p.motion_deg, 4)} for p in result.sync.suspects]
    written[0].write_text(json.dumps(doc, indent=2) + "\n")
    write_report(result, written[1])
    write_html(result, written[2], written[1].name)
    if not result.passed:
        for name in _PASS_ONLY:
            (outdir / name).unlink(missing_ok=True)
        shutil.rmtree(outdir / "camera_info", ignore_errors=True)
        return written
    fs = cv2.FileStorage(str(outdir / "calibration.yaml"), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", c.image_size[0])
    fs.write("image_height", c.image_size[1])
    fs.write("lens_model", c.lens_model)
    for key, value in (("K1", c.K_left), ("D1", c.D_left.reshape(1, -1)), ("K2", c.K_right),
                       ("D2", c.D_right.reshape(1, -1)), ("R", c.R), ("T", c.T.reshape(3, 1)), ("R1", r.R1),
                       ("R2", r.R2), ("P1", r.P1), ("P2", r.P2), ("Q", r.Q)):
        fs.write(key, np.asarray(value, dtype=np.float64))
    for key in ("rms_left", "rms_right", "rms_stereo", "epipolar_rms_px", "epipolar_all_rms_px"):
        fs.write(key, float(getattr(q, key)))
    fs.release()
    (outdir / "left.yaml").write_text(ros_camera_info("left", c.image_size, c.K_left, c.D_left, r.R1, r.P1, c.lens_model))
    (outdir / "right.yaml").write_text(ros_camera_info("right", c.image_size, c.K_right, c.D_right, r.R2, r.P2, c.lens_model))
    camchain = kalibr_camchain(c)
    if camchain is not None:
        (outdir / "camchain.yaml").write_text(camchain)
    extra = [p for size in sizes or () for p in write_camera_info(c, outdir / "camera_info", size)]
    return written + [outdir / n for n in _PASS_ONLY if (outdir / n).exists()] + extra
