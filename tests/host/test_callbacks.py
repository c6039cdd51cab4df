"""FrameCallbacks on their own (no camera): what a callback raises never ends delivery, and close()
waits for a running callback within its bound, then says which one still runs."""
from __future__ import annotations

import logging
import threading
import types

import pytest

from stereocam.callbacks import FrameCallbacks
from stereocam.protocol.errors import CallbackError
from stereocam.tools.conformance.budget import budget
from tests.support.waiting import wait_until


def frame(n: int) -> types.SimpleNamespace:
    return types.SimpleNamespace(sequence=n)  # all FrameCallbacks reads of a frame


@pytest.fixture
def callbacks():
    cbs = FrameCallbacks(depth=4, name="test-callbacks")
    yield cbs
    cbs.close(timeout=budget(5))


@pytest.mark.parametrize("exc", [SystemExit("bye"), KeyboardInterrupt(), GeneratorExit()])
def test_a_base_exception_is_counted_re_raised_by_check_and_delivery_goes_on(callbacks, exc, caplog):
    """SystemExit killed the thread: not counted, check() said nothing, later callbacks got nothing."""
    def leave(f):
        raise exc

    seen: list[int] = []
    callbacks.add(leave)
    callbacks.add(lambda f: seen.append(f.sequence))
    with caplog.at_level(logging.ERROR):
        callbacks.put(frame(1))
        wait_until(lambda: seen == [1], 10, "the second callback called after the first raised")
    assert callbacks.errors == 1 and "raised on frame 1" in caplog.text
    with pytest.raises(CallbackError) as info:
        callbacks.check()
    assert info.value.__cause__ is exc
    callbacks.remove(leave)
    callbacks.put(frame(2))
    wait_until(lambda: seen == [1, 2], 10, "the next frame delivered")
    assert callbacks.errors == 1


def test_close_waits_for_a_running_callback_that_returns_in_time(callbacks):
    started, release = threading.Event(), threading.Event()
    done: list[int] = []

    def slow(f):
        started.set()
        release.wait(budget(10))
        done.append(f.sequence)

    callbacks.add(slow)
    callbacks.put(frame(1))
    assert started.wait(budget(10))
    threading.Timer(0.2, release.set).start()
    assert callbacks.close(timeout=budget(10)) is True  # the thread has ended
    assert done == [1]


def test_close_names_a_callback_that_outlives_its_wait_and_calls_none_after(callbacks, caplog):
    """close() returned after 2 s with the thread alive and no word about it."""
    started, release = threading.Event(), threading.Event()
    calls: list[int] = []

    def stuck(f):
        calls.append(f.sequence)
        started.set()
        release.wait(budget(30))

    callbacks.add(stuck)
    callbacks.put(frame(1))
    assert started.wait(budget(10))
    callbacks.put(frame(2))  # queued behind the running call: never delivered after close()
    with caplog.at_level(logging.WARNING):
        assert callbacks.close(timeout=0.1) is False
    assert "stuck" in caplog.text and "still runs on frame 1" in caplog.text
    release.set()
    wait_until(lambda: not callbacks._thread.is_alive(), 10, "the thread ends once the callback returns")
    assert calls == [1]


def test_close_from_within_a_callback_returns_at_once(callbacks):
    returned = threading.Event()

    def closer(f):
        callbacks.close()
        returned.set()

    callbacks.add(closer)
    callbacks.put(frame(1))
    assert returned.wait(budget(10))
    wait_until(lambda: not callbacks._thread.is_alive(), 10, "the thread ends after the callback")


def test_a_callback_registered_twice_is_called_once_per_frame(callbacks):
    seen: list[int] = []

    def keep(f):
        seen.append(f.sequence)

    callbacks.add(keep)
    callbacks.add(keep)
    callbacks.put(frame(1))
    callbacks.put(frame(2))
    wait_until(lambda: len(seen) >= 2, 10, "both frames delivered")
    callbacks.put(frame(3))
    wait_until(lambda: 3 in seen, 10, "the third frame delivered")
    assert seen == [1, 2, 3]
    assert callbacks.remove(keep) and not callbacks.remove(keep)  # once registered, once removed
