"""A kernel worker on another worker's CPU moves off it for the frame, and the calling thread
gives it its CPU mask back after (stereocam.stereo.cpus), with the real system calls on real
threads."""
from __future__ import annotations

import os
import sys
import threading

import numba as nb
import numpy as np
import pytest

from stereocam.stereo import cpus

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux system calls")


@nb.njit
def _worker_sees_worker_0_on_its_cpu(caller, where, masks, pinned, slot, workers=2):
    """As worker 1 of ``workers``, with worker 0 (slot 0) or the caller at the launch (slot
    ``workers``) on record on this thread's CPU: spread_out, then the CPU and mask it ended
    on. pinned: first allow only those CPUs (none: as it is)."""
    before = np.zeros(cpus.MASK_WORDS, np.uint64)
    cpus.get_affinity(0, before)
    if pinned.size:
        some = np.zeros(cpus.MASK_WORDS, np.uint64)
        for c in pinned:
            some[c // 64] |= np.uint64(1) << np.uint64(c % 64)
        cpus.set_affinity(0, some)
        cpus.get_affinity(0, before)
    c0 = cpus.current_cpu()
    where[slot * cpus.WHERE_STRIDE] = c0
    state = cpus.spread_out(1, workers, caller, where, masks[1])
    moved_to = cpus.current_cpu()
    during = np.zeros(cpus.MASK_WORDS, np.uint64)
    cpus.get_affinity(0, during)
    return state, c0, moved_to, before, during


@nb.njit
def _restore(where, masks, workers):
    cpus.restore(where, masks, workers)


def _allowed(words: np.ndarray) -> set[int]:
    return {64 * i + b for i, w in enumerate(words) for b in range(64) if int(w) >> b & 1}


def _on_a_thread(caller: int, pinned: tuple[int, ...] = (), slot: int = 0,
                 workers: int = 2) -> tuple:
    """Worker 1 on a new thread; once it has decided, this thread (the caller) restores the
    masks while the worker thread still runs, and reads the worker's mask after."""
    where = np.full((workers + 1) * cpus.WHERE_STRIDE, -1, np.int64)
    masks = np.zeros((workers, 2, cpus.MASK_WORDS), np.uint64)
    out: list = []
    decided, restored = threading.Event(), threading.Event()

    def worker() -> None:
        out.append(_worker_sees_worker_0_on_its_cpu(
            np.uint64(caller), where, masks, np.array(pinned, np.int64), slot, workers))
        out.append(threading.get_native_id())
        decided.set()
        restored.wait(timeout=120)

    t = threading.Thread(target=worker)
    t.start()
    try:
        assert decided.wait(timeout=120), "the worker thread did not decide"
        _restore(where, masks, workers)
        after = os.sched_getaffinity(out[1])
    finally:
        restored.set()
        t.join(timeout=120)
    return out[0] + (after, where, out[1])


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs two allowed CPUs")
@pytest.mark.parametrize("slot", [0, 2], ids=["worker-0", "caller-at-launch"])  # of 2 workers
def test_a_pool_thread_on_another_workers_cpu_moves_off_it_and_gets_its_mask_back(slot) -> None:
    state, c0, moved_to, before, during, after, where, tid = _on_a_thread(
        threading.get_ident(), slot=slot)
    assert state == cpus.MOVED
    assert where[cpus.WHERE_STRIDE] == c0  # its own CPU on record
    assert where[cpus.WHERE_STRIDE + 1] == tid  # and its thread, for restore
    assert moved_to != c0
    assert _allowed(during) == _allowed(before) - {c0}
    assert after == _allowed(before) == os.sched_getaffinity(0)


def test_a_thread_allowed_one_cpu_stays() -> None:
    cpu = min(os.sched_getaffinity(0))
    state, c0, moved_to, before, during, after, where, _ = _on_a_thread(threading.get_ident(),
                                                                        (cpu,))
    assert state == cpus.STAY
    assert c0 == moved_to == cpu
    assert where[cpus.WHERE_STRIDE + 1] == -1  # nothing to restore
    assert _allowed(before) == _allowed(during) == after == {cpu}


def test_the_thread_that_called_the_kernel_never_moves() -> None:
    """The caller's thread is the user's: it keeps its CPU on record and stays."""
    where = np.full(3 * cpus.WHERE_STRIDE, -1, np.int64)
    masks = np.zeros((2, 2, cpus.MASK_WORDS), np.uint64)
    mine = os.sched_getaffinity(0)
    state, c0, moved_to, *_ = _worker_sees_worker_0_on_its_cpu(
        np.uint64(threading.get_ident()), where, masks, np.zeros(0, np.int64), 0)
    assert state == 0
    assert where[cpus.WHERE_STRIDE] == where[2 * cpus.WHERE_STRIDE] == c0
    assert os.sched_getaffinity(0) == mine


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs two allowed CPUs")
def test_with_more_workers_than_allowed_cpus_a_worker_stays() -> None:
    """Three workers on two CPUs share one anyway: pinning one would only add to it."""
    two = tuple(sorted(os.sched_getaffinity(0))[:2])
    state, c0, moved_to, before, during, after, where, _ = _on_a_thread(threading.get_ident(),
                                                                        two, workers=3)
    assert state == cpus.STAY
    assert where[cpus.WHERE_STRIDE + 1] == -1
    assert _allowed(before) == _allowed(during) == after == set(two)
