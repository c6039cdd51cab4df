"""Device mode tells the operator within seconds that the board is not in view (issue 20), and gives up
when it never was."""
from __future__ import annotations

import pytest

from stereocam.tools.calibration.device import NO_BOARD_GIVE_UP, NO_BOARD_WARN_EVERY, BoardWatch
from stereocam.tools.calibration.solve import BoardNotFoundError, Progress, ViewRecord


def progress(i: int, status: str) -> Progress:
    return Progress(ViewRecord(i, f"pair {i}", status), 0, 0, ())


def test_a_run_without_the_board_warns_every_few_seconds_and_ends() -> None:
    said: list[str] = []
    seen: list[Progress] = []
    watch = BoardWatch(seen.append, fps=10, warn=said.append)
    with pytest.raises(BoardNotFoundError, match=f"first {NO_BOARD_GIVE_UP} captures"):
        for i in range(NO_BOARD_GIVE_UP + 50):
            watch(progress(i, "no_board"))
    assert len(seen) == NO_BOARD_GIVE_UP  # every pair reached the caller's progress first
    assert len(said) == (NO_BOARD_GIVE_UP - 1) // NO_BOARD_WARN_EVERY  # the end is said by the error
    assert said[0] == (f"warning: no board in both images in the last {NO_BOARD_WARN_EVERY} captures "
                       f"({NO_BOARD_WARN_EVERY / 10:.0f} s): is it in view of both cameras?")


def test_a_board_seen_once_keeps_the_run_going_and_restarts_the_count() -> None:
    said: list[str] = []
    watch = BoardWatch(None, fps=10, warn=said.append)
    watch(progress(0, "used"))
    for i in range(1, 2 * NO_BOARD_GIVE_UP):
        watch(progress(i, "no_board" if i % NO_BOARD_WARN_EVERY else "redundant"))
    assert not said  # never NO_BOARD_WARN_EVERY in a row
    for i in range(NO_BOARD_WARN_EVERY):
        watch(progress(i, "dropped"))
    assert len(said) == 1
