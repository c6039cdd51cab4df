"""STEREOCAM_DETECTION_CACHE: a second detection of the same image and board reads the disk, not
the detectors; another image, board or a spoilt entry detects again; unset, nothing is written."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from stereocam.tools.calibration import boards
from stereocam.tools.calibration.board_text import parse_board
from stereocam.tools.calibration.boards import detect_all
from stereocam.tools.calibration.detection_cache import ENV
from tests.support.paths import DATA

IMAGE = DATA / "opencv_chessboard_pairs" / "left01.jpg"


@pytest.fixture
def counted(monkeypatch) -> dict[str, int]:
    """The chessboard detectors, counting their calls."""
    calls = {name: 0 for name in boards.CHESSBOARD_DETECTORS}

    def counting(name, detector):
        def run(g, board):
            calls[name] += 1
            return detector(g, board)
        return run

    monkeypatch.setattr(boards, "CHESSBOARD_DETECTORS",
                        {n: counting(n, d) for n, d in boards.CHESSBOARD_DETECTORS.items()})
    return calls


def _same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(
        np.array_equal(getattr(a[k], f), getattr(b[k], f)) and getattr(a[k], f).dtype == getattr(b[k], f).dtype
        for k in a for f in ("ids", "image_points", "object_points"))


def test_a_second_detection_reads_the_cache(tmp_path: Path, monkeypatch, counted) -> None:
    monkeypatch.setenv(ENV, str(tmp_path))
    img, board = cv2.imread(str(IMAGE), cv2.IMREAD_GRAYSCALE), parse_board("9x6", 0.025)
    first = detect_all(img, board)
    assert set(first) == {"classic", "sector", "sector_subpix"} and counted == {"classic": 1, "sector": 1}
    again = detect_all(img.copy(), parse_board("9x6", 0.025))
    assert _same(first, again) and counted == {"classic": 1, "sector": 1}
    other_board = detect_all(img, parse_board("9x6", 0.03))  # other object points: detected again
    assert counted == {"classic": 2, "sector": 2}
    assert np.allclose(other_board["classic"].object_points, first["classic"].object_points * 0.03 / 0.025)
    flipped = detect_all(img[::-1].copy(), board)  # another image
    assert counted == {"classic": 3, "sector": 3} and set(flipped) == {"classic", "sector", "sector_subpix"}


def test_a_spoilt_entry_is_a_miss_and_is_rewritten(tmp_path: Path, monkeypatch, counted) -> None:
    monkeypatch.setenv(ENV, str(tmp_path))
    img, board = cv2.imread(str(IMAGE), cv2.IMREAD_GRAYSCALE), parse_board("9x6", 0.025)
    first = detect_all(img, board)
    (entry,) = tmp_path.glob("*.npz")
    entry.write_bytes(entry.read_bytes()[:100])
    assert _same(detect_all(img, board), first) and counted["classic"] == 2
    assert _same(detect_all(img, board), first) and counted["classic"] == 2  # rewritten whole


def test_no_board_found_is_cached_too_and_unset_writes_nothing(tmp_path: Path, monkeypatch, counted) -> None:
    blank = np.full((120, 160), 128, np.uint8)
    board = parse_board("9x6", 0.025)
    monkeypatch.delenv(ENV, raising=False)
    assert detect_all(blank, board) == {} and detect_all(blank, board) == {} and counted["classic"] == 2
    monkeypatch.setenv(ENV, str(tmp_path / "cache"))
    assert detect_all(blank, board) == {} and detect_all(blank, board) == {} and counted["classic"] == 3
    assert len(list((tmp_path / "cache").glob("*.npz"))) == 1
