"""The frame dispatcher: every listener gets every frame into its own bounded queue, under its own
drop policy, with its own drop count; a slow listener never holds up the others."""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from stereocam.dispatch import DropPolicy, FrameDispatcher, FrameQueue
from stereocam.frame_types import DisparityFormat, Frame, FrameStatus, StereoGeometry
from stereocam.protocol.errors import ConfigError
from tests.support.waiting import wait_until


def frame(seq: int) -> Frame:
    img = np.zeros((2, 2), np.uint8)
    return Frame(seq, 0, seq * 1000, float(seq), img, img, None, 100, 1, 2, 2, False,
                 DisparityFormat(4, 0, 16, -1), StereoGeometry(1.0, 0.0, 0.0, 0.1, 0), FrameStatus.COMPLETE)


def drain(q: FrameQueue) -> list[int]:
    out = []
    while (f := q.get(0)) is not None:
        out.append(f.sequence)
    return out


def test_each_listener_keeps_its_own_queue_policy_and_drops():
    d = FrameDispatcher()
    oldest = FrameQueue("oldest", 3, DropPolicy.DROP_OLDEST)
    newest = FrameQueue("newest", 3, DropPolicy.DROP_NEWEST)
    slot = FrameQueue("slot", 5, DropPolicy.KEEP_NEWEST)  # a slot holds one frame whatever the size asked
    big = FrameQueue("big", 100)
    for q in (oldest, newest, slot, big):
        d.add(q)
    for seq in range(1, 11):
        d.dispatch(frame(seq))
    assert (oldest.dropped, newest.dropped, slot.dropped, big.dropped) == (7, 7, 9, 0)
    assert drain(oldest) == [8, 9, 10]
    assert drain(newest) == [1, 2, 3]
    assert drain(slot) == [10]
    assert drain(big) == list(range(1, 11))


def test_a_removed_listener_gets_nothing_and_the_others_go_on():
    d = FrameDispatcher()
    a, b = FrameQueue("a"), FrameQueue("b")
    d.add(a)
    d.add(b)
    d.dispatch(frame(1))
    d.remove(a)
    d.dispatch(frame(2))
    assert drain(a) == [1] and drain(b) == [1, 2] and a not in d and b in d


def test_a_slow_listener_does_not_stall_the_others():
    d = FrameDispatcher()
    slow_taken: list[int] = []
    released: list[bool] = []
    release = threading.Event()
    slow = FrameQueue("slow", 2, DropPolicy.DROP_OLDEST)
    fast = FrameQueue("fast", 1000)
    d.add(slow)
    d.add(fast)

    def slow_consumer():  # takes one frame, then blocks as a stuck callback would
        f = slow.get(5)
        slow_taken.append(f.sequence)
        released.append(release.wait(10))

    t = threading.Thread(target=slow_consumer, daemon=True)
    t.start()
    d.dispatch(frame(0))
    wait_until(lambda: slow_taken, 5, "the slow consumer took a frame")
    for seq in range(1, 501):
        d.dispatch(frame(seq))
    release.set()
    t.join(5)
    assert slow_taken == [0]
    assert drain(fast) == list(range(0, 501))  # every frame, in order, none dropped
    assert slow.dropped == 498 and drain(slow) == [499, 500]
    assert released == [True]  # the dispatching never waited on the stuck consumer


def test_a_listener_that_raises_is_logged_and_the_others_still_get_the_frame(caplog):
    class Broken:
        def put(self, _frame: Frame) -> None:
            raise RuntimeError("bug in a listener")

    d = FrameDispatcher()
    q = FrameQueue("q")
    d.add(Broken())
    d.add(q)
    d.dispatch(frame(7))
    assert drain(q) == [7]
    assert any("bug in a listener" in r.getMessage() for r in caplog.records)


def test_get_waits_until_a_frame_comes_or_the_timeout():
    q = FrameQueue("q")
    t0 = time.monotonic()
    assert q.get(0.05) is None and time.monotonic() - t0 >= 0.04
    threading.Timer(0.05, q.put, (frame(3),)).start()
    got = q.get(5)
    assert got is not None and got.sequence == 3


def test_bad_arguments_are_config_errors():
    with pytest.raises(ConfigError):
        FrameQueue("q", 0)
    with pytest.raises(ConfigError):
        FrameQueue("q", 4, "drop-oldest")  # type: ignore[arg-type]
