"""Per-row spin locks, atomics on int32 arrays and a bounded spin-wait, as numba intrinsics, for
the SGM kernels' threads (sgm.py's path groups, sgm_one_pass.py's chains)."""
from __future__ import annotations

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from .simd import X86, _call, _ix, _ptr

_I32 = ir.IntType(32)


def _lock_ptr(context, builder, sig, args):
    return _ptr(context, builder, sig.args[0], args[0], [_ix(context, builder, sig, args, 1)])


@intrinsic
def try_lock(typingctx, locks, i):
    """Atomically set locks[i] from 0 to 1 (acquire); True when this call took the lock."""
    if not (isinstance(locks, types.Array) and locks.dtype == types.int32):
        return None

    def codegen(context, builder, sig, args):
        res = builder.cmpxchg(_lock_ptr(context, builder, sig, args), ir.Constant(_I32, 0),
                              ir.Constant(_I32, 1), "acq_rel", "monotonic")
        return builder.extract_value(res, 1)

    return types.boolean(locks, i), codegen


@intrinsic
def unlock(typingctx, locks, i):
    """Release locks[i] (store 0 with release ordering)."""
    if not (isinstance(locks, types.Array) and locks.dtype == types.int32):
        return None

    def codegen(context, builder, sig, args):
        builder.store_atomic(ir.Constant(_I32, 0), _lock_ptr(context, builder, sig, args),
                             "release", 4)
        return context.get_dummy_value()

    return types.none(locks, i), codegen


@intrinsic
def fetch_add(typingctx, arr, i, v):
    """arr[i] += v atomically (int32, acquire and release: what this thread wrote before is
    seen by a thread whose later fetch_add returns this one's result); returns the value
    before."""
    if not (isinstance(arr, types.Array) and arr.dtype == types.int32):
        return None

    def codegen(context, builder, sig, args):
        val = context.cast(builder, args[2], sig.args[2], types.int32)
        old = builder.atomic_rmw("add", _lock_ptr(context, builder, sig, args), val, "acq_rel")
        return builder.sext(old, ir.IntType(64))

    return types.int64(arr, i, v), codegen


@intrinsic
def load_acquire(typingctx, arr, i):
    """arr[i] (int32), read with acquire ordering."""
    if not (isinstance(arr, types.Array) and arr.dtype == types.int32):
        return None

    def codegen(context, builder, sig, args):
        v = builder.load_atomic(_lock_ptr(context, builder, sig, args), "acquire", 4)
        return builder.sext(v, ir.IntType(64))

    return types.int64(arr, i), codegen


@intrinsic
def store_release(typingctx, arr, i, v):
    """arr[i] = v (int32), written with release ordering."""
    if not (isinstance(arr, types.Array) and arr.dtype == types.int32):
        return None

    def codegen(context, builder, sig, args):
        val = context.cast(builder, args[2], sig.args[2], types.int32)
        builder.store_atomic(val, _lock_ptr(context, builder, sig, args), "release", 4)
        return context.get_dummy_value()

    return types.none(arr, i, v), codegen


SPINS = 2000  # spin_wait's PAUSEs (some microseconds) before it gives the core away


@intrinsic
def spin_wait(typingctx, n):
    """One step of a wait loop, the n-th (from 1): a PAUSE for the first SPINS, then
    sched_yield, which lets a descheduled thread that the loop waits for have the core
    (spinning beside a busy process would keep it from it). Linux and other POSIX systems."""
    if not isinstance(n, types.Integer):
        return None

    def codegen(context, builder, sig, args):
        n64 = context.cast(builder, args[0], sig.args[0], types.int64)
        spin = builder.icmp_signed("<=", n64, ir.Constant(n64.type, SPINS))
        with builder.if_else(spin) as (then, otherwise):
            with then:
                if X86:
                    _call(builder, "llvm.x86.sse2.pause", ir.VoidType(), [])
            with otherwise:
                fn = cgutils.get_or_insert_function(builder.module,
                                                    ir.FunctionType(_I32, []), "sched_yield")
                builder.call(fn, [])
        return context.get_dummy_value()

    return types.none(n), codegen
