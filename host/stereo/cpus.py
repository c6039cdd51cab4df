"""Which CPU a kernel's worker runs on, and moving a worker off a CPU another worker of the
same frame already runs on (numba intrinsics over the C library; Linux, elsewhere no-ops).

Why: on a machine with as many CPUs as workers and one busy process, Linux's load balancer
counts tasks, so it leaves the busy process alone on one CPU and both workers sharing the
other (2 tasks against 1 looks balanced): the frame gets one core. A worker that sees this
moves itself, for the rest of the frame, to an allowed CPU no worker of the frame is on; the
calling thread gives it its own CPU mask back once the frame is done (restore). Only pool
threads move: never the thread that called the kernel (the user's), and never outside the
CPUs the thread was allowed.
"""
from __future__ import annotations

import sys
from typing import Any

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import types

from .jit import KERNEL
from .lanes import intrinsic
from .simd import _call, _ptr

LINUX = sys.platform.startswith("linux")
MASK_WORDS = 16  # a cpu_set_t: 1024 CPUs
WHERE_STRIDE = 16  # where[t * WHERE_STRIDE]: worker t's CPU, each on its own cache line
_I64 = ir.IntType(64)


def _int_of(name: str) -> Any:
    """An intrinsic returning the C library's int ``name()`` as int64 (-1 outside Linux)."""
    @intrinsic
    def call(typingctx):
        def codegen(context, builder, sig, args):
            if not LINUX:
                return ir.Constant(_I64, -1)
            return builder.sext(_call(builder, name, ir.IntType(32), []), _I64)

        return types.int64(), codegen
    return call


current_cpu = _int_of("sched_getcpu")
current_cpu.__doc__ = "The CPU this thread runs on now (sched_getcpu), -1 where unknown."
thread_id = _int_of("gettid")
thread_id.__doc__ = "The calling thread's kernel id (gettid), -1 where unknown."


@intrinsic
def this_thread(typingctx):
    """pthread_self() of the calling thread (threading.get_ident() on POSIX); 0 elsewhere."""
    def codegen(context, builder, sig, args):
        if not LINUX:
            return ir.Constant(_I64, 0)
        return _call(builder, "pthread_self", _I64, [])

    return types.uint64(), codegen


def _affinity(name: str) -> Any:
    @intrinsic
    def call(typingctx, tid, mask):
        if not (isinstance(mask, types.Array) and mask.ndim == 1 and mask.dtype == types.uint64):
            return None

        def codegen(context, builder, sig, args):
            if not LINUX:
                return ir.Constant(_I64, -1)
            p = builder.bitcast(_ptr(context, builder, sig.args[1], args[1],
                                     [ir.Constant(_I64, 0)]), ir.IntType(8).as_pointer())
            i32 = ir.IntType(32)
            r = _call(builder, name, i32,
                      [builder.trunc(args[0], i32), ir.Constant(_I64, 8 * MASK_WORDS), p])
            return builder.sext(r, _I64)

        return types.int64(types.int64, mask), codegen
    return call


get_affinity = _affinity("sched_getaffinity")
get_affinity.__doc__ = ("The allowed CPUs of thread tid (kernel id; 0: the calling thread) into mask\n"
                        "(MASK_WORDS uint64); 0 on success.")
set_affinity = _affinity("sched_setaffinity")
set_affinity.__doc__ = ("Allow thread tid (kernel id; 0: the calling thread) only the CPUs in mask; 0 on\n"
                        "success.")

STAY, MOVED = 1, 2  # spread_out's outcomes (0: not decided yet)


@nb.njit(**KERNEL)
def _count(mask: np.ndarray) -> int:
    """CPUs in mask."""
    n = 0
    for w in mask:
        while w:
            w &= w - np.uint64(1)
            n += 1
    return n


@nb.njit(**KERNEL)
def spread_out(t: int, workers: int, caller: np.uint64, where: np.ndarray,
               masks: np.ndarray) -> int:
    """Worker t records its CPU in where (a slot per worker, then the caller's: note_cpu);
    a pool thread (not caller) sharing its CPU with another worker or the caller moves to an
    allowed CPU none of them is on (saving its mask in masks[0], the new one in masks[1],
    and its kernel thread id in the slot after its CPU, for restore). Returns the new
    state: 0 (call again on the next row), STAY or MOVED (call no more this frame)."""
    cpu = current_cpu()
    where[t * WHERE_STRIDE] = cpu
    if cpu < 0:
        return STAY
    if this_thread() == caller:  # never moves; keeps its CPU on record
        where[workers * WHERE_STRIDE] = cpu
        return 0
    shared = False
    for u in range(workers + 1):  # slot ``workers``: the caller's CPU at the launch (note_cpu)
        if u != t and where[u * WHERE_STRIDE] == cpu:
            shared = True
    if not shared:
        return 0
    if get_affinity(0, masks[0]) != 0 or _count(masks[0]) < workers:
        return STAY  # more workers than CPUs: sharing is unavoidable, pinning would add to it
    masks[1, :] = masks[0]
    for u in range(workers + 1):
        c = where[u * WHERE_STRIDE]
        if 0 <= c < 64 * MASK_WORDS:
            masks[1, c // 64] &= ~(np.uint64(1) << np.uint64(c % 64))
    if not masks[1].any() or set_affinity(0, masks[1]) != 0:
        return STAY
    where[t * WHERE_STRIDE + 1] = thread_id()
    return MOVED


@nb.njit(**KERNEL)
def note_cpu(where: np.ndarray, slot: int) -> None:
    """Put the calling thread's CPU on record in where's slot (before launching the workers:
    the worker woken on the caller's CPU often runs first, the caller waiting behind it)."""
    where[slot * WHERE_STRIDE] = current_cpu()


@nb.njit(**KERNEL)
def restore(where: np.ndarray, masks: np.ndarray, workers: int) -> None:
    """Give each of the workers that moved (where: spread_out's, masks[t]: worker t's) its
    own CPU mask back; the caller does it once every worker is done. A worker restoring its
    own mask is requeued by the scheduler: beside a busy process it then often waited a
    whole slice (0.5-6 ms) before reaching the frame's end, and the frame with it."""
    for t in range(workers):
        tid = where[t * WHERE_STRIDE + 1]
        if tid > 0:
            set_affinity(tid, masks[t, 0])
