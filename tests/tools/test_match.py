"""``stereocam match``: a disparity map from two image files, equal to the library's engines and
post-processing, written as KITTI PNG, PFM or .npy and read back by the bench's truth loader."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from stereocam.stereo import MatchParams, SGMParams, match  # noqa: E402
from stereocam.stereo.post import POST_PRESETS, postprocess, post_params_from_config  # noqa: E402
from stereocam.protocol.errors import ConfigError  # noqa: E402
from stereocam.protocol.params import defaults  # noqa: E402
from stereocam.stereo import engines  # noqa: E402
from stereocam.tools.bench.matching_report import class_scene  # noqa: E402
from stereocam.tools.image_files import read_disparity  # noqa: E402
from stereocam.tools.image_files import write_disparity, write_whole  # noqa: E402
from tests.tools.test_cli import stereocam as run  # noqa: E402


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, np.ndarray, np.ndarray]:
    scene = class_scene("slanted", 128, 96, seed=2)
    folder = tmp_path_factory.mktemp("pair")
    left, right = folder / "left.png", folder / "right.png"
    assert cv2.imwrite(str(left), cv2.cvtColor(scene.left, cv2.COLOR_GRAY2BGR))  # colour is turned grey
    assert cv2.imwrite(str(right), scene.right)
    return left, right, scene.left, scene.right


def _px(disp: np.ndarray, invalid: int) -> np.ndarray:
    return np.where(disp == invalid, np.nan, disp / 16).astype(np.float32)


def test_every_format_holds_the_engines_map(files, tmp_path: Path) -> None:
    left, right, a, b = files
    want = _px(match(a, b, SGMParams(num_disparities=32)), SGMParams(num_disparities=32).invalid_value)
    assert np.isfinite(want).mean() > 0.8 and np.isnan(want).any()
    for name in ("d.npy", "d.pfm", "d.png"):
        r = run("match", str(left), str(right), "--out", str(tmp_path / name), "--num-disparities", "32")
        assert r.returncode == 0, r.stderr
        assert f"{name}: 128x96, sgm, preset off" in r.stdout
        got = np.load(tmp_path / name) if name.endswith(".npy") else read_disparity(tmp_path / name, None)
        exact = np.where(want == 0, 1 / 256, want) if name.endswith(".png") else want  # PNG: 0 is no match
        np.testing.assert_array_equal(got, exact)  # 1/16 px steps are exact in every format
    assert (want == 0).any()  # the zero disparity case was met


def test_block_matching_and_a_preset(files, tmp_path: Path) -> None:
    left, right, a, b = files
    r = run("match", str(left), str(right), "--out", str(tmp_path / "bm.npy"), "--algorithm", "bm",
            "--num-disparities", "32", "--set", "block_size=9", "--set", "uniqueness_ratio=5")
    assert r.returncode == 0, r.stderr
    p = MatchParams(num_disparities=32, block_size=9, uniqueness_ratio=5)
    np.testing.assert_array_equal(np.load(tmp_path / "bm.npy"), _px(match(a, b, p), p.invalid_value))
    r = run("match", str(left), str(right), "--out", str(tmp_path / "hd.npy"), "--preset", "high_density",
            "--num-disparities", "32", "--preview", str(tmp_path / "hd.png"))
    assert r.returncode == 0, r.stderr
    assert "100.0 % of pixels matched" in r.stdout and " ms (one run, " in r.stdout
    picture = cv2.imread(str(tmp_path / "hd.png"))
    assert picture.shape == (96, 128, 3) and len(np.unique(picture.reshape(-1, 3), axis=0)) > 10
    cfg = {**defaults(), **POST_PRESETS["high_density"], "num_disparities": 32}
    ep = engines.params_from_config(cfg)
    want = postprocess(match(a, b, ep), a, post_params_from_config(cfg), b, ep)
    np.testing.assert_array_equal(np.load(tmp_path / "hd.npy"), _px(want, ep.invalid_value))
    assert not np.isnan(np.load(tmp_path / "hd.npy")).any()


@pytest.mark.parametrize("extra, code, words", [
    (["--out", "{t}/d.jpg"], 2, "one of .png, .pfm, .npy"),
    (["--out", "{t}/d.png", "--min-disparity", "-16"], 2, "no negative disparity"),
    (["--out", "{t}/d.npy", "--num-disparities", "40"], 2, "40 is not a multiple of 16"),
    (["--out", "{t}/d.npy", "--num-disparities", "256"], 2, "disparity range"),
    (["--out", "{t}/none/d.npy"], 2, "is not a folder"),
    (["--out", "{t}/d.npy", "--set", "exposure_us=100"], 2, "exposure_us: not a matching parameter"),
    (["--out", "{t}/d.npy", "--preview", "{t}/d.txt"], 2, "a picture is .png or .jpg"),
    (["--out", "{t}/d.npy", "--set", "block_size=8"], 2, "block_size"),
    (["--out", "{t}/d.npy", "--set", "sgm_p2=999"], 2, "sgm_p2"),
])
def test_mistakes_exit_with_a_message(files, tmp_path: Path, extra: list[str], code: int, words: str) -> None:
    left, right, _, _ = files
    r = run("match", str(left), str(right), *[a.format(t=tmp_path) for a in extra])
    assert r.returncode == code, r.stderr
    assert words in r.stderr and "Traceback" not in r.stderr
    assert not list(tmp_path.glob("d.*"))


def test_a_failed_write_keeps_the_file_there(tmp_path: Path) -> None:
    old = tmp_path / "d.png"
    old.write_bytes(b"the previous map")
    with pytest.raises(ConfigError, match="negative"):  # refused after matching, before the file is touched
        write_disparity(old, np.array([[-1.0, 2.0]], np.float32))
    boom = np.zeros((2, 2), np.float32)

    def failing(path: Path) -> None:
        path.write_bytes(b"half")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        write_whole(old, failing)
    assert old.read_bytes() == b"the previous map" and [p.name for p in tmp_path.iterdir()] == ["d.png"]
    write_disparity(old, boom)  # a good write replaces it whole
    assert read_disparity(old, None).shape == (2, 2) and [p.name for p in tmp_path.iterdir()] == ["d.png"]


def test_damaged_and_mismatched_images_exit_1(files, tmp_path: Path) -> None:
    left, _, a, _ = files
    fake, small, fifo = tmp_path / "fake.png", tmp_path / "small.png", tmp_path / "fifo.png"
    fake.write_text("not an image")
    cv2.imwrite(str(small), a[:, :100])
    os.mkfifo(fifo)  # would block a plain read for ever
    for other, words in ((fake, "fake.png: not an image"), (small, "128x96 but"), (fifo, "not a regular file")):
        r = run("match", str(left), str(other), "--out", str(tmp_path / "d.npy"))
        assert r.returncode == 1 and words in r.stderr and "Traceback" not in r.stderr, r.stderr
        assert not (tmp_path / "d.npy").exists()
