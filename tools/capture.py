"""``stereocam capture URL --out DIR``: grab frames and write what a user looks at first."""
from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

import stereocam


def colorize(frame: stereocam.Frame) -> np.ndarray:
    """Disparity as a TURBO colour map (near = warm), invalid pixels black."""
    d = frame.disparity_px()
    fmt = frame.disparity_format
    lo, hi = fmt.min_disparity, fmt.min_disparity + fmt.num_disparities
    norm = np.nan_to_num((d - lo) / max(hi - lo, 1), nan=0.0)
    img = cv2.applyColorMap((np.clip(norm, 0, 1) * 255).astype(np.uint8), cv2.COLORMAP_TURBO)
    img[np.isnan(d)] = 0
    return img


def save_frame(frame: stereocam.Frame, out: Path, stem: str = "frame") -> dict[str, Path]:
    """left/right PNG, disparity .npy (raw int16) and colour PNG, point cloud .ply."""
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    for name, img in (("left", frame.left), ("right", frame.right)):
        if img is not None:
            paths[name] = out / f"{stem}_{name}.png"
            cv2.imwrite(str(paths[name]), img)
    if frame.disparity is not None:
        paths["disparity_npy"] = out / f"{stem}_disparity.npy"
        np.save(paths["disparity_npy"], frame.disparity)
        paths["disparity_png"] = out / f"{stem}_disparity.png"
        cv2.imwrite(str(paths["disparity_png"]), colorize(frame))
        paths["ply"] = out / f"{stem}_points.ply"
        stereocam.write_ply(paths["ply"], *frame.points())
    return paths


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="stereocam capture", description=__doc__.splitlines()[0])
    ap.add_argument("url")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--count", type=int, default=1, help="frames to save")
    ap.add_argument("--timeout", type=float, default=30.0, help="seconds to wait for each frame (the first pays JIT warm-up)")
    args = ap.parse_args(argv)
    with stereocam.open(args.url, timeout=2.0) as cam:
        cam.set_trigger_mode("software")
        cam.start()
        for i in range(args.count):
            cam.trigger()
            frame = cam.get_frame(timeout=args.timeout)
            paths = save_frame(frame, args.out, f"frame{frame.sequence:06d}")
            print(f"sequence {frame.sequence}: " + ", ".join(str(p) for p in paths.values()))
        cam.stop()
    return 0
