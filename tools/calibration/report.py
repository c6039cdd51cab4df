"""The calibration's pictures and page: report.png (matplotlib: metrics, per-view errors named by
file with the worst views called out, coverage, a rectified pair with epipolar lines) and
report.html beside it (the same figures as tables, every dropped pair with its reason)."""
from __future__ import annotations

import html
from pathlib import Path

import cv2
import numpy as np

from stereocam.tools.calibration.coverage import PARAM_NAMES
from stereocam.tools.calibration.lens import rectify_map
from stereocam.tools.calibration.solve import CalibrationResult, ViewRecord

WIDTH_PX, DPI = 1280, 100
WORST = 3  # views called out by name
COLOURS = {"left reprojection": "#2878c8", "right reprojection": "#3caa3c", "held-out epipolar": "#f08c1e"}


def short_label(view: ViewRecord) -> str:
    """A pair's name on an axis: the left file's name ("left_07.jpg|right_07.jpg" -> "left_07.jpg")."""
    return view.label.split("|")[0].strip().rsplit("/", 1)[-1] or f"pair {view.index}"


def view_errors(view: ViewRecord) -> dict[str, float]:
    """The per-view errors (px) the report shows for ``view``."""
    out = {"left reprojection": view.rms_left, "right reprojection": view.rms_right,
           "held-out epipolar": view.epipolar_rms_px if view.held_out else None}
    return {k: float(v) for k, v in out.items() if v is not None}


def worst_views(result: CalibrationResult, n: int = WORST) -> list[tuple[ViewRecord, str, float]]:
    """The ``n`` used views with the largest error: (view, which error, px)."""
    ranked = []
    for v in (v for v in result.views if v.status == "used"):
        errs = view_errors(v)
        if errs:
            name = max(errs, key=lambda n: errs[n])
            ranked.append((v, name, errs[name]))
    return sorted(ranked, key=lambda t: -t[2])[:n]


def _summary(result: CalibrationResult) -> tuple[str, str]:
    q, c = result.quality, result.calibration
    verdict = "PASSED" if result.passed else "FAILED: " + "; ".join(result.failures)
    line = (f"RMS left {q.rms_left:.3f} px, right {q.rms_right:.3f} px, stereo {q.rms_stereo:.3f} px; "
            f"held-out epipolar {q.epipolar_rms_px:.3f} px; {q.views_used} pairs used, {q.views_dropped} dropped; "
            f"{c.lens_model}; fx {c.K_left[0, 0]:.1f} px; baseline {c.baseline_m * 1000:.2f} mm; "
            f"{c.image_size[0]}x{c.image_size[1]}")
    return verdict, line


def _rectified_pair(result: CalibrationResult) -> np.ndarray | None:
    if result.sample_pair is None:
        return None
    c, r = result.calibration, result.rectification
    halves = [cv2.remap(img, *rectify_map(c.lens_model, K, D, R, P, c.image_size), cv2.INTER_LINEAR)
              for img, K, D, R, P in ((result.sample_pair[0], c.K_left, c.D_left, r.R1, r.P1),
                                      (result.sample_pair[1], c.K_right, c.D_right, r.R2, r.P2))]
    return np.hstack(halves)


def write_report(result: CalibrationResult, path: Path) -> None:
    """Draw report.png at ``path`` (1280 px wide)."""
    from matplotlib.figure import Figure  # no pyplot: no global state, safe from any thread

    pair = _rectified_pair(result)
    views = [v for v in result.views if v.status == "used"]
    pair_h = 0.0 if pair is None else 12.8 * pair.shape[0] / pair.shape[1]
    fig = Figure(figsize=(WIDTH_PX / DPI, 1.0 + 3.4 + 1.8 + pair_h), dpi=DPI)
    grid = fig.add_gridspec(4 if pair is not None else 3, 1, height_ratios=[1.0, 3.4, 1.8] + ([pair_h] if pair_h else []),
                            hspace=0.55, left=0.06, right=0.99, top=0.99, bottom=0.01)
    verdict, line = _summary(result)
    head = fig.add_subplot(grid[0])
    head.axis("off")
    head.text(0, 0.75, verdict, fontsize=13, weight="bold", color="green" if result.passed else "firebrick",
              transform=head.transAxes, wrap=True)
    head.text(0, 0.35, line, fontsize=9, transform=head.transAxes)
    dropped = "; ".join(f"{short_label(v)} ({v.reason})" for v in result.dropped)
    if dropped:
        head.text(0, -0.05, "dropped: " + dropped, fontsize=8, color="firebrick", transform=head.transAxes,
                  wrap=True)

    ax = fig.add_subplot(grid[1])
    x = np.arange(len(views))
    width = 0.27
    for k, (name, colour) in enumerate(COLOURS.items()):
        values = [view_errors(v).get(name, np.nan) for v in views]
        ax.bar(x + (k - 1) * width, values, width, label=name, color=colour)
    ax.set_xticks(x, [short_label(v) for v in views], rotation=60 if len(views) > 12 else 0, ha="right"
                  if len(views) > 12 else "center", fontsize=7 if len(views) > 12 else 8)
    ax.set_ylabel("RMS error (px)")
    ax.set_title("per-view error of the pairs used (held-out pairs also show their epipolar error)", fontsize=9)
    ax.legend(fontsize=8, loc="upper center", ncol=3)
    ax.grid(axis="y", alpha=0.3)
    top = max([e for v in views for e in view_errors(v).values()] or [0.2])
    ax.set_ylim(0, top * 1.45)
    for v, name, value in worst_views(result):
        i = views.index(v)
        side = "left" if i < len(views) / 3 else "right" if i > 2 * len(views) / 3 else "center"
        ax.annotate(f"worst: {short_label(v)} {value:.2f} px ({name})", (i, value), xytext=(0, 8),
                    textcoords="offset points", ha=side, fontsize=7, color="firebrick", annotation_clip=False,
                    arrowprops=dict(arrowstyle="-", color="firebrick", lw=0.8))

    cov = fig.add_subplot(grid[2])
    cov.barh(list(PARAM_NAMES), [100 * c for c in result.coverage],
             color=["#3caa3c" if c >= 1 else "#f08c1e" for c in result.coverage])
    cov.set_xlim(0, 100)
    cov.set_xlabel("coverage of the pairs used (%, ROS-style: X, Y, size, skew)")
    cov.invert_yaxis()
    for k, c in enumerate(result.coverage):
        cov.text(min(100 * c + 1, 92), k, f"{100 * c:.0f} %", va="center", fontsize=8)

    if pair is not None:
        img = fig.add_subplot(grid[3])
        img.imshow(pair, cmap="gray", vmin=0, vmax=255, aspect="auto")
        h, w = pair.shape
        img.hlines(np.arange(h / 16, h, h / 16), 0, w - 1, colors="orange", linewidth=0.5)
        img.axvline(w / 2, color="white", linewidth=1.5)
        img.set_title("rectified pair (left | right) with epipolar lines: a feature sits on the same line in both",
                      fontsize=9)
        img.axis("off")
    fig.savefig(path, dpi=DPI)


def write_html(result: CalibrationResult, path: Path, picture: str = "report.png") -> None:
    """report.html: the verdict, every metric, the lens models tried, each pair's fate and errors."""
    esc = html.escape
    verdict, line = _summary(result)
    rows = []
    for v in result.views:
        errs = view_errors(v)
        cells = [short_label(v), v.status + (" (held out)" if v.held_out else "")]
        cells += [f"{errs[k]:.3f}" if k in errs else "" for k in COLOURS]
        cells.append(v.reason or "")
        rows.append("<tr>" + "".join(f"<td>{esc(c)}</td>" for c in cells) + "</tr>")
    worst = "".join(f"<li>{esc(short_label(v))}: {value:.3f} px {esc(name)}</li>"
                    for v, name, value in worst_views(result))
    scores = "".join(f"<li>{esc(m)}: {s:.4f} px{' (chosen)' if m == result.calibration.lens_model else ''}</li>"
                     for m, s in result.model_scores.items())
    scores += "".join(f"<li>{esc(m)}: failed ({esc(why)})</li>" for m, why in result.model_failures.items())
    note = result.sync.message() if result.sync is not None else None
    sync = f'<h2>Synchronisation</h2><p class="warning">{esc(note)}</p>' if note else ""
    colour = "green" if result.passed else "firebrick"
    path.write_text(f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>stereo calibration report</title>
<style>body{{font-family:sans-serif;margin:1.5em}} td,th{{padding:2px 8px;text-align:left}}
tr:nth-child(even){{background:#f3f3f3}} .verdict{{color:{colour};font-weight:bold;font-size:1.3em}} .warning{{color:firebrick}}</style>
</head><body>
<p class="verdict">{esc(verdict)}</p>
<p>{esc(line)}</p>
<h2>Worst views</h2><ul>{worst}</ul>
<h2>Lens models (held-out score)</h2><ul>{scores}</ul>
{sync}
<h2>Every pair</h2>
<table><tr><th>pair</th><th>status</th>{''.join(f'<th>{esc(k)} (px)</th>' for k in COLOURS)}<th>why dropped</th></tr>
{''.join(rows)}
</table>
<h2>Pictures</h2><img src="{esc(picture)}" alt="per-view errors, coverage and the rectified pair" style="max-width:100%">
</body></html>
""")
