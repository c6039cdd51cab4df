"""The matching bench's per-scene report: its scores on crafted disparities, and its tables
(columns, every engine, parsable numbers) on a small scene class, from the function and the CLI."""
from __future__ import annotations

import numpy as np
import pytest

from stereocam.tools.bench.matching_report import (CV2_INVALID, COLUMNS, LIDAR_FRACTION, LIDAR_MIN_PX, REFERENCE,
                                                   SGBM_MODES, class_scene, lidar_subset, misaligned, report,
                                                   score)
from tests.tools.test_cli import stereocam as run

NAME_W, CELL_W = 24, 11  # format_table's column widths


def parse_tables(text: str) -> dict[str, dict[str, list[float]]]:
    """scene title -> method -> the numbers of its row."""
    tables: dict[str, dict[str, list[float]]] = {}
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if line.startswith("== "):
            head = lines[i + 1]
            assert [head[:NAME_W].strip()] + [head[NAME_W + CELL_W * k:NAME_W + CELL_W * (k + 1)].strip()
                                             for k in range(len(COLUMNS) - 1)] == list(COLUMNS)
            rows = tables.setdefault(line.strip("= ").split(",")[0], {})
            for row in lines[i + 3:]:
                if not row.strip() or row.startswith(("==", "load average", "(")):
                    break
                cells = [row[NAME_W + CELL_W * k:NAME_W + CELL_W * (k + 1)].strip() for k in range(len(COLUMNS) - 1)]
                rows[row[:NAME_W].strip()] = [float("nan") if c == "-" else float(c) for c in cells]
    return tables


def test_score_counts_invalid_as_bad_over_all_truth_and_not_over_reported():
    truth = np.array([[10.0, 10.0, 10.0, np.nan]], np.float32)
    disp = np.array([[160, 16 * 13, CV2_INVALID, 0]], np.int16)  # exact, 3 px off, invalid, no truth
    density, bad_all, bad_rep, epe = score(disp, CV2_INVALID, truth)
    assert density == 75.0
    assert bad_all == pytest.approx(200 / 3)  # 3 px off and invalid, of the 3 with truth
    assert bad_rep == 50.0 and epe == 1.5  # of the 2 reported with truth


def test_report_prints_one_parsable_table_per_scene_with_every_engine(capsys):
    rows = report([lambda: class_scene("thin", 128, 96, seed=1)], threads=1, repeat=1, busy=False)
    out = capsys.readouterr().out
    assert "load average" in out and "numba" in out and "cv2" in out and "threads 1" in out
    table = parse_tables(out)["thin 128x96"]
    expected = {"ours bm 9x9", "ours sgm 8 paths", "ours sgm 4 paths", "cv2 StereoBM 9x9",
                *(f"cv2 {mode}" for mode in SGBM_MODES)}
    assert expected <= set(table)
    assert table[REFERENCE][-1] == 1.0  # the ratio column is relative to SGBM_3WAY
    for row in rows[0]:
        density, bad_all, bad_rep, epe, ms, spread, ratio = table[row.method]
        assert (density, bad_all, bad_rep) == pytest.approx((row.density, row.bad_all, row.bad_reported), abs=0.051)
        assert bad_all >= 100 - density - 0.1  # every invalid pixel with truth is bad
        assert bad_rep <= bad_all + 0.1 and ms > 0 and spread == 0  # one timed run: no spread


def test_cli_runs_the_report_for_the_scenes_asked_and_beside_a_busy_process():
    r = run("bench", "matching", "--algorithm", "sgm", "--scenes", "slanted", "--size", "128", "96",
            "--repeat", "2", "--threads", "2", "--busy")
    assert r.returncode == 0, r.stderr
    assert "beside a busy process" in r.stdout and "threads 2" in r.stdout
    assert list(parse_tables(r.stdout)) == ["slanted 128x96"]


def test_lidar_subset_keeps_a_sparse_share_mostly_low_in_the_image_and_nothing_from_the_sky():
    truth = np.full((120, 160), 20.0, np.float32)
    truth[:30] = LIDAR_MIN_PX / 10  # sky
    truth[100:, :10] = np.nan  # no truth
    sparse = lidar_subset(truth, seed=3)
    kept = np.isfinite(sparse)
    assert kept.mean() == pytest.approx(LIDAR_FRACTION, rel=0.15)
    assert not kept[:30].any() and not kept[100:, :10].any()
    assert kept[60:].sum() > 2 * kept[:60].sum()  # mostly the lower image
    assert np.array_equal(sparse[kept], truth[kept])
    assert np.array_equal(kept, np.isfinite(lidar_subset(truth, seed=3)))
    assert not np.array_equal(kept, np.isfinite(lidar_subset(truth, seed=4)))


def test_cli_scores_driving_on_its_range_and_on_a_sparse_truth_with_a_vertical_error():
    r = run("bench", "matching", "--algorithm", "sgm", "--scenes", "driving", "--size", "160", "120",
            "--repeat", "1", "--threads", "1", "--sparse-truth", "--vertical-error", "1")
    assert r.returncode == 0, r.stderr
    assert "== driving 160x120 sparse right +1 px, 32 disparities, truth on 7 % of 160x120 ==" in r.stdout
    assert "ours sgm 5 paths" in parse_tables(r.stdout)["driving 160x120 sparse right +1 px"]


def test_a_vertical_error_moves_the_right_image_and_keeps_the_truth():
    scene = class_scene("slanted", 96, 64, seed=0)
    down, up = misaligned(scene, 1.0), misaligned(scene, -2.0)
    assert np.array_equal(down.right[1:], scene.right[:-1]) and np.array_equal(down.right[0], scene.right[0])
    assert np.array_equal(up.right[:-2], scene.right[2:]) and np.array_equal(up.right[-1], scene.right[-1])
    half = misaligned(scene, 0.5).right.astype(int)  # bilinear: between the rows, rounded
    assert np.abs(half[1:] - (scene.right[1:].astype(int) + scene.right[:-1]) / 2).max() <= 0.5
    assert down.left is scene.left and down.truth is scene.truth and down.name == "slanted 96x64 right +1 px"
    assert misaligned(scene, 0.0) is scene


def test_cli_names_an_unknown_scene():
    r = run("bench", "matching", "--algorithm", "sgm", "--scenes", "marble")
    assert r.returncode == 2 and "marble" in r.stderr and "low-texture" in r.stderr and "Traceback" not in r.stderr
