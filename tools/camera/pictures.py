"""Pictures a user looks at: disparity colour-mapped with a colour bar in metres."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

import stereocam


def disparity_range(frame: stereocam.Frame) -> tuple[float, float]:
    """The disparities (px) the matcher searched: the colour map's ends."""
    fmt = frame.disparity_format
    return float(fmt.min_disparity), float(fmt.min_disparity + fmt.num_disparities)


def colorize(frame: stereocam.Frame, span: tuple[float, float] | None = None) -> np.ndarray:
    """Disparity as a TURBO colour map (near = warm), BGR uint8, invalid pixels black; ``span``:
    the disparities (px) at the map's ends, else the searched range."""
    return colorize_px(frame.disparity_px(), span or disparity_range(frame))


def colorize_px(d: np.ndarray, span: tuple[float, float]) -> np.ndarray:
    """Disparities ``d`` (px, NaN no match) as a TURBO colour map from span[0] to span[1], BGR uint8,
    no match black."""
    lo, hi = span
    norm = np.nan_to_num((d - lo) / max(hi - lo, 1), nan=0.0)
    img = cv2.applyColorMap((np.clip(norm, 0, 1) * 255).astype(np.uint8), cv2.COLORMAP_TURBO)
    img[np.isnan(d)] = 0
    return img


def depth_ticks(frame: stereocam.Frame, count: int = 7,
                span: tuple[float, float] | None = None) -> list[tuple[float, float]]:
    """(disparity px, depth m) pairs for a colour bar labelled in metres: round depths whose
    disparities fall inside ``span`` (default: the searched range), near to far, at least
    1/``count`` of the bar apart."""
    lo, hi = span or disparity_range(frame)
    fb = frame.geometry.focal_px * frame.geometry.baseline_m
    if fb <= 0:
        return []
    gap = (hi - lo) / count
    candidates = [m * 10.0 ** e for e in range(-2, 3) for m in (1, 1.5, 2, 3, 5, 7)]
    ticks: list[tuple[float, float]] = []
    for z in candidates:
        d = fb / z
        if lo < d <= hi and (not ticks or ticks[-1][0] - d >= gap):
            ticks.append((d, round(z, 3)))
    return ticks


def save_disparity_png(frame: stereocam.Frame, path: Path) -> Path:
    """The colour-mapped disparity with a colour bar whose ticks read depth in metres."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure  # no pyplot: no global state, safe from any thread

    lo, hi = disparity_range(frame)
    rgb = cv2.cvtColor(colorize(frame), cv2.COLOR_BGR2RGB)
    fig = Figure(figsize=(frame.width / 100 + 1.6, frame.height / 100 + 0.6), dpi=100)
    ax = fig.add_subplot()
    ax.imshow(rgb)
    ax.set_axis_off()
    ax.set_title(f"disparity, frame {frame.sequence} (black: no match)", fontsize=9)
    mappable = ScalarMappable(Normalize(lo, hi), cmap="turbo")
    bar = fig.colorbar(mappable, ax=ax, fraction=0.05, pad=0.02)
    ticks = depth_ticks(frame)
    bar.set_ticks([d for d, _ in ticks], labels=[f"{z:g}" for _, z in ticks])
    bar.set_label("depth (m)")
    fig.savefig(path, bbox_inches="tight")
    return path
