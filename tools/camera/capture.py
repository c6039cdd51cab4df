"""stereocam capture URL --out DIR: grab frames and write what a user looks at first."""
from __future__ import annotations

import json
from pathlib import Path

import click
import cv2
import numpy as np
from tqdm import tqdm

import stereocam
from stereocam.tools.options import CONTEXT, Finite, epilog
from stereocam.tools.progress import progress_wanted

from .pictures import save_disparity_png
from .session import output_dir, preserved_configuration


def save_frame(frame: stereocam.Frame, out: Path, stem: str = "frame") -> dict[str, Path]:
    """left/right PNG, disparity .npy (raw int16) and colour PNG with a depth scale, point cloud .ply."""
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    for name, img in (("left", frame.left), ("right", frame.right)):
        if img is not None:
            paths[name] = out / f"{stem}_{name}.png"
            cv2.imwrite(str(paths[name]), img)
    if frame.disparity is not None:
        paths["disparity_npy"] = out / f"{stem}_disparity.npy"
        np.save(paths["disparity_npy"], frame.disparity)
        paths["disparity_png"] = save_disparity_png(frame, out / f"{stem}_disparity.png")
        paths["ply"] = out / f"{stem}_points.ply"
        stereocam.write_ply(paths["ply"], *frame.points())
    return paths


@click.command("capture", epilog=epilog(), context_settings=CONTEXT)
@click.argument("url")
@click.option("--out", type=click.Path(path_type=Path), required=True,
              help="Directory for the files; created if missing (checked before the camera is opened).")
@click.option("--count", type=click.IntRange(min=1), default=1, show_default=True, help="Frames to save (at least 1).")
@click.option("--timeout", type=Finite(0, min_open=True), default=30.0, show_default=True,
              help="Seconds to wait for each frame (the first pays the matcher's warm-up).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON array (sequence and files per frame) at the end.")
def command(url: str, out: Path, count: int, timeout: float, as_json: bool) -> int:
    """Software-trigger COUNT frames and save each: left/right PNG, disparity .npy and PNG (colour bar
    in metres), point cloud .ply. The camera's configuration (trigger mode included) is restored after."""
    output_dir(out)
    with stereocam.open(url, timeout=2.0) as cam, preserved_configuration(cam):
        cam.set_trigger_mode("software")
        cam.start()
        saved = []
        with tqdm(total=count, unit="frame", desc="capture", disable=not progress_wanted()) as bar:
            for _ in range(count):
                cam.trigger()
                frame = cam.get_frame(timeout=timeout)
                paths = save_frame(frame, out, f"frame{frame.sequence:06d}")
                saved.append({"sequence": frame.sequence, "files": {k: str(p) for k, p in paths.items()}})
                if not as_json:
                    bar.write(f"sequence {frame.sequence}: " + ", ".join(str(p) for p in paths.values()))
                bar.update()
    if as_json:
        click.echo(json.dumps(saved, indent=2))
    return 0
