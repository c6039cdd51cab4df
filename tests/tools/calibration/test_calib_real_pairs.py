"""The offline calibration tool on real camera images: OpenCV's 13 sample chessboard pairs."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from tests.support.paths import DATA

PAIRS = DATA / "opencv_chessboard_pairs"


def calibrate(out: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "stereocam.tools.cli", "calibrate", "--images", str(PAIRS), "--board", "9x6",
                           "--square-size", "0.025", "--out", str(out), "-q", *extra],
                          capture_output=True, text=True, timeout=300)


def test_a_strict_gate_says_why_it_fails(tmp_path):
    r = calibrate(tmp_path, "--max-epipolar", "0.05", "--lens-model", "plumb_bob")  # the gate, not the model race
    assert r.returncode == 4, r.stderr
    assert "FAILED the gate" in r.stderr and "epipolar" in r.stderr
    doc = json.loads((tmp_path / "calibration.json").read_text())
    assert doc["passed"] is False and doc["written"] is False
    assert doc["epipolar_rms_px"] > 0.05 and (tmp_path / "report.png").exists()
    assert not (tmp_path / "calibration.yaml").exists()


def test_real_pairs_pass_the_default_gate_with_the_readme_example(tmp_path):
    """The README's offline example, as written there: its --min-views only matters in device mode,
    so this is the default gate (one solve for what were two tests of the same one)."""
    r = calibrate(tmp_path, "--min-views", "6")
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "calibration.json").read_text())
    assert doc["passed"] is True and doc["image_size"] == [640, 480]
    assert 0.05 < doc["rms_left"] < 0.5 and 0.05 < doc["rms_right"] < 0.5 and doc["rms_stereo"] < 0.5
    baseline = sum(t * t for t in doc["T"]) ** 0.5
    assert 0.075 < baseline < 0.09  # OpenCV's stereo_calib finds |T| ~ 3.3 squares on this set
    assert doc["T"][0] < 0  # right camera to the right of the left one
    for name in ("calibration.yaml", "left.yaml", "right.yaml", "report.png"):
        assert (tmp_path / name).exists()
    page = (tmp_path / "report.html").read_text()
    for d in doc["dropped"]:  # each dropped file named with its reason, on the page and in the picture's caption
        assert d["pair"].split("|")[0] in page and d["reason"].split(" ")[0] in page
    used = [f"left{n:02d}.jpg" for n in range(1, 15) if f"left{n:02d}.jpg" not in str(doc["dropped"])]
    assert sum(name in page for name in used) >= 10
    assert page.count("<li>") >= 3 + 1 and "(chosen)" in page  # the worst views; the lens models that fitted


def test_the_same_images_give_the_same_solution_bit_for_bit():
    """OpenCV's threaded solver sums in varying order; on an ill-conditioned rational fit that moved
    the outliers and the model scores between identical runs. The tool's solves are reproducible."""
    import cv2
    import numpy as np

    from stereocam.tools.calibration.lens import calibrate_mono

    grid = np.zeros((54, 3), np.float32)
    grid[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * 0.025
    corners = []
    for path in sorted(PAIRS.glob("left*.jpg")):
        img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        found, c = cv2.findChessboardCorners(img, (9, 6))
        if found:
            corners.append(cv2.cornerSubPix(img, c, (11, 11), (-1, -1), (3, 30, 0.001)))
    fits = [calibrate_mono("rational_polynomial", [grid] * len(corners), corners, (640, 480)) for _ in range(4)]
    assert all(np.array_equal(f.K, fits[0].K) and np.array_equal(f.D, fits[0].D) and f.rms == fits[0].rms
               for f in fits[1:])


def test_a_set_with_no_readable_pair_is_a_usage_error_naming_the_files(tmp_path):
    """Files that are not images at all: exit 2 (the help's "unreadable images"), each pair named
    with its reason, not "the board was not found"."""
    for i in range(3):
        for side in ("left", "right"):
            (tmp_path / f"{side}{i}.png").write_text("hi")
    r = subprocess.run([sys.executable, "-m", "stereocam.tools.cli", "calibrate", "--images", str(tmp_path), "--board",
                        "9x6", "--square-size", "0.025", "--out", str(tmp_path / "out"), "--db",
                        str(tmp_path / "f.sqlite")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "none of the 3 pairs could be used" in r.stderr, r.stderr
    assert "left0.png|right0.png: cannot read the left image" in r.stderr and "board was not found" not in r.stderr
    assert "(cannot read the left image)" in r.stdout  # the pair's line says why it was dropped


def test_an_unreadable_file_or_an_odd_size_drops_its_pair_not_the_set(tmp_path):
    """A corrupt JPEG and a pair resized by mistake, among good pairs: both dropped, named and said
    why; the rest calibrates and passes."""
    import shutil

    import cv2

    images = tmp_path / "images"
    shutil.copytree(PAIRS, images)
    (images / "left03.jpg").write_bytes(b"\xff\xd8 not really a jpeg")
    right = cv2.imread(str(images / "right07.jpg"), cv2.IMREAD_GRAYSCALE)
    cv2.imwrite(str(images / "right07.jpg"), cv2.resize(right, (320, 240)))
    r = subprocess.run([sys.executable, "-m", "stereocam.tools.cli", "calibrate", "--images", str(images), "--board",
                        "9x6", "--square-size", "0.025", "--out", str(tmp_path / "out"), "-q", "--lens-model",
                        "plumb_bob"], capture_output=True, text=True, timeout=300)  # the dropping, not the model race
    assert r.returncode == 0, r.stderr
    dropped = {d["pair"].split("|")[0]: d["reason"] for d in json.loads((tmp_path / "out" / "calibration.json")
                                                                       .read_text())["dropped"]}
    assert dropped["left03.jpg"] == "cannot read the left image"
    assert dropped["left07.jpg"] == "left 640x480 and right 320x240 differ"
