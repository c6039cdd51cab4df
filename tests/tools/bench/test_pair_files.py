"""The matching bench on pairs of files (--pair, --truth): the truth formats of the public sets and
their unknowns, sizes checked, and the same table as the built-in scene the files were written from."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from stereocam.protocol.errors import InputFileError  # noqa: E402
from stereocam.tools.bench.matching_report import class_scene  # noqa: E402
from stereocam.tools.bench.pair_files import DEFAULT_DISPARITIES, pair_scene, range_for  # noqa: E402
from stereocam.tools.image_files import read_disparity  # noqa: E402
from tests.tools.bench.test_matching_report import parse_tables  # noqa: E402
from tests.tools.test_cli import stereocam as run  # noqa: E402

TRUTH = np.array([[10.25, np.inf, 3.5], [np.nan, 47.75, 0.5]], np.float32)


def test_truth_from_pfm_kitti_png_and_npy_with_their_unknowns(tmp_path: Path) -> None:
    want = np.where(np.isfinite(TRUTH), TRUTH, np.nan)
    assert cv2.imwrite(str(tmp_path / "d.pfm"), TRUTH)
    np.testing.assert_array_equal(read_disparity(tmp_path / "d.pfm", None), want)
    np.save(tmp_path / "d.npy", TRUTH)
    np.testing.assert_array_equal(read_disparity(tmp_path / "d.npy", None), want)
    np.testing.assert_array_equal(read_disparity(tmp_path / "d.npy", 2.0), want / 2)
    kitti = np.where(np.isfinite(TRUTH), TRUTH * 256, 0).astype(np.uint16)  # 0: no LiDAR return
    assert cv2.imwrite(str(tmp_path / "d.png"), kitti)
    np.testing.assert_array_equal(read_disparity(tmp_path / "d.png", None), want)
    eight = np.array([[40, 0], [8, 200]], np.uint8)  # Middlebury 2003: disparity x 4, 0 unknown
    assert cv2.imwrite(str(tmp_path / "e.png"), eight)
    with pytest.raises(InputFileError, match="--truth-scale"):
        read_disparity(tmp_path / "e.png", None)
    np.testing.assert_array_equal(read_disparity(tmp_path / "e.png", 4.0), [[10, np.nan], [2, 50]])


def test_damaged_and_mismatched_files_are_refused_naming_them(tmp_path: Path) -> None:
    scene = class_scene("slanted", 96, 64, seed=0)
    left, right, small = tmp_path / "l.png", tmp_path / "r.png", tmp_path / "s.png"
    cv2.imwrite(str(left), scene.left)
    cv2.imwrite(str(right), scene.right)
    cv2.imwrite(str(small), scene.right[:, :80])
    with pytest.raises(InputFileError, match="96x64 but .*s.png is 80x64"):
        pair_scene(left, small, None, None, None)
    fake = tmp_path / "fake.png"
    fake.write_text("not an image")
    with pytest.raises(InputFileError, match="fake.png: not an image"):
        pair_scene(left, fake, None, None, None)
    np.save(tmp_path / "t.npy", np.zeros((64, 95), np.float32))
    with pytest.raises(InputFileError, match="t.npy is 95x64 but the images are 96x64"):
        pair_scene(left, right, tmp_path / "t.npy", None, None)
    np.save(tmp_path / "c.npy", np.zeros((64, 96, 3), np.float32))
    with pytest.raises(InputFileError, match="2-D"):
        pair_scene(left, right, tmp_path / "c.npy", None, None)
    os.mkfifo(tmp_path / "f.npy")
    with pytest.raises(InputFileError, match="not a regular file"):
        pair_scene(left, right, tmp_path / "f.npy", None, None)
    (tmp_path / "x.npy").write_bytes(b"\x93NUMPY garbage")
    with pytest.raises(InputFileError, match="x.npy: not a numpy array file"):
        pair_scene(left, right, tmp_path / "x.npy", None, None)


def test_the_range_goes_past_the_truths_largest_disparity() -> None:
    assert range_for(np.array([[47.5, np.nan]], np.float32)) == 48
    assert range_for(np.array([[48.0, 3.0]], np.float32)) == 64
    assert range_for(np.array([[0.5]], np.float32)) == 16
    assert range_for(None) == range_for(np.full((2, 2), np.nan, np.float32)) == DEFAULT_DISPARITIES


def test_a_pair_of_files_gets_the_table_of_the_scene_they_were_written_from(tmp_path: Path) -> None:
    scene = class_scene("thin", 128, 96, seed=1)
    paths = [tmp_path / n for n in ("left.png", "right.png", "truth.pfm")]
    colour = cv2.cvtColor(scene.left, cv2.COLOR_GRAY2BGR)  # a colour file is turned grey
    assert cv2.imwrite(str(paths[0]), colour) and cv2.imwrite(str(paths[1]), scene.right)
    assert cv2.imwrite(str(paths[2]), scene.truth)
    r = run("bench", "matching", "--algorithm", "sgm", "--scenes", "thin", "--size", "128", "96", "--seed", "1",
            "--pair", str(paths[0]), str(paths[1]), "--truth", str(paths[2]),
            "--num-disparities", str(scene.num_disparities), "--repeat", "1", "--threads", "1")
    assert r.returncode == 0, r.stderr
    assert f"== left.png, {scene.num_disparities} disparities, truth on " in r.stdout
    tables = parse_tables(r.stdout)
    files, built_in = tables["left.png"], tables["thin 128x96"]
    assert set(files) == set(built_in) and "ours sgm 5 paths" in files and "cv2 SGBM_3WAY" in files
    for method, row in files.items():  # density, bad-2.0 all, bad-2.0 reported, EPE: the same matches
        assert row[:4] == pytest.approx(built_in[method][:4], abs=1e-9), method


def test_a_pair_without_truth_gets_density_and_time_only(tmp_path: Path) -> None:
    scene = class_scene("slanted", 128, 96, seed=0)
    left, right = tmp_path / "a.png", tmp_path / "b.png"
    cv2.imwrite(str(left), scene.left)
    cv2.imwrite(str(right), scene.right)
    r = run("bench", "matching", "--algorithm", "sgm", "--pair", str(left), str(right), "--num-disparities", "32",
            "--repeat", "1", "--threads", "1")
    assert r.returncode == 0, r.stderr
    table = parse_tables(r.stdout)
    assert list(table) == ["a.png"]  # the pairs replace the built-in scenes
    density, bad_all, bad_rep, epe, ms, _, _ = table["a.png"]["ours sgm 5 paths"]
    assert density > 50 and ms > 0 and np.isnan([bad_all, bad_rep, epe]).all()


@pytest.mark.parametrize("extra, code, words", [
    (["--truth", "{l}", "--truth", "{l}"], 2, "2 --truth for 1 --pair"),
    (["--num-disparities", "50"], 2, "50 is not a multiple of 16"),
    (["--algorithm", "bm"], 2, "go with --algorithm sgm"),
    (["--truth", "{t}"], 1, "needs --truth-scale"),
    (["--truth", "{missing}"], 2, "does not exist"),
    (["--num-disparities", "64"], 2, "leaves no column of width 64"),  # before the JIT warm-up
])
def test_cli_mistakes_exit_with_a_message(tmp_path: Path, extra: list[str], code: int, words: str) -> None:
    left, truth = tmp_path / "l.png", tmp_path / "t.png"
    cv2.imwrite(str(left), np.zeros((48, 64), np.uint8))
    cv2.imwrite(str(truth), np.zeros((48, 64), np.uint8))
    fill = {"l": str(left), "t": str(truth), "missing": str(tmp_path / "none.pfm")}
    args = ["bench", "matching", "--pair", str(left), str(left), *[a.format(**fill) for a in extra]]
    if "--algorithm" not in extra:
        args += ["--algorithm", "sgm"]
    r = run(*args)
    assert r.returncode == code, r.stderr
    assert words in r.stderr and "Traceback" not in r.stderr
