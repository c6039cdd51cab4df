"""Vector operations over the disparity axis for the SGM kernels, plus a per-row spin lock.

Arrays are 1-D int16 with the disparity axis contiguous; ``nd`` is a multiple of 16 and each
loop walks it in 64/32/16-lane chunks (simd._chunked). Callers guarantee indices are in range,
including the one padding element before and after each ``prev`` run that path_step reads.
"""
from __future__ import annotations

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from .simd import _TAIL, _call, _chunked, _fold16, _ptr, _reduce_min, _smin, _splat, _vload, \
    _vstore

_I16 = ir.IntType(16)
_I32 = ir.IntType(32)


def _i16_arrays(*tys) -> bool:
    return all(isinstance(t, types.Array) and t.ndim == 1 and t.dtype == types.int16
               for t in tys)


def _intp(context, builder, sig, args, i):
    return context.cast(builder, args[i], sig.args[i], types.intp)


def _i16(context, builder, sig, args, i):
    return context.cast(builder, args[i], sig.args[i], types.int16)


@intrinsic
def path_step(typingctx, cost, ci, prev, pi, out, oi, acc, ai, init, p1, p2m, mprev, nd):
    """One SGM path step for all nd disparities of one pixel; returns min_k of the new L:

        L[k] = cost[ci+k] + min(prev[pi+k], min(prev[pi+k-1], prev[pi+k+1]) + p1, p2m) - mprev
        out[oi+k] = L[k];  acc[ai+k] = L[k] if init else acc[ai+k] + L[k]

    with p2m = mprev + P2 (the caller's effective P2) and mprev = min_k prev[pi+k]."""
    if not _i16_arrays(cost, prev, out, acc):
        return None

    def codegen(context, builder, sig, args):
        st = sig.args
        civ, piv, oiv, aiv = (_intp(context, builder, sig, args, i) for i in (1, 3, 5, 7))
        init_b = builder.icmp_signed("!=", _intp(context, builder, sig, args, 8),
                                     ir.Constant(ir.IntType(64), 0))
        p1v, p2v, mpv = (_i16(context, builder, sig, args, i) for i in (9, 10, 11))
        ndv = _intp(context, builder, sig, args, 12)
        one = ir.Constant(ndv.type, 1)
        best = cgutils.alloca_once_value(builder, _splat(builder, ir.Constant(_I16, 32767),
                                              ir.VectorType(_I16, _TAIL)))

        def body(j0, n):
            vty = ir.VectorType(_I16, n)
            pj = builder.add(piv, j0)
            pv = _vload(builder, _ptr(context, builder, st[2], args[2], [pj]), vty)
            lo = _vload(builder, _ptr(context, builder, st[2], args[2], [builder.sub(pj, one)]),
                        vty)
            hi = _vload(builder, _ptr(context, builder, st[2], args[2], [builder.add(pj, one)]),
                        vty)
            v = _smin(builder, pv, builder.add(_smin(builder, lo, hi), _splat(builder, p1v, vty)))
            v = _smin(builder, v, _splat(builder, p2v, vty))
            c = _vload(builder, _ptr(context, builder, st[0], args[0], [builder.add(civ, j0)]),
                       vty)
            L = builder.sub(builder.add(c, v), _splat(builder, mpv, vty))
            _vstore(builder, L, _ptr(context, builder, st[4], args[4], [builder.add(oiv, j0)]))
            pa = _ptr(context, builder, st[6], args[6], [builder.add(aiv, j0)])
            a = builder.select(init_b, L, builder.add(_vload(builder, pa, vty), L))
            _vstore(builder, a, pa)
            builder.store(_smin(builder, builder.load(best), _fold16(builder, L)), best)

        _chunked(builder, ndv, body)
        return _reduce_min(builder, builder.load(best))

    return types.int16(cost, ci, prev, pi, out, oi, acc, ai, init, p1, p2m, mprev, nd), codegen


@intrinsic
def add_min(typingctx, dst, di, src, si, nd):
    """dst[di+k] += src[si+k] for k < nd; returns min_k of the new dst values."""
    if not _i16_arrays(dst, src):
        return None

    def codegen(context, builder, sig, args):
        st = sig.args
        div, siv, ndv = (_intp(context, builder, sig, args, i) for i in (1, 3, 4))
        best = cgutils.alloca_once_value(builder, _splat(builder, ir.Constant(_I16, 32767),
                                              ir.VectorType(_I16, _TAIL)))

        def body(j0, n):
            vty = ir.VectorType(_I16, n)
            pd = _ptr(context, builder, st[0], args[0], [builder.add(div, j0)])
            s = _vload(builder, _ptr(context, builder, st[2], args[2], [builder.add(siv, j0)]),
                       vty)
            t = builder.add(_vload(builder, pd, vty), s)
            _vstore(builder, t, pd)
            builder.store(_smin(builder, builder.load(best), _fold16(builder, t)), best)

        _chunked(builder, ndv, body)
        return _reduce_min(builder, builder.load(best))

    return types.int16(dst, di, src, si, nd), codegen


@intrinsic
def diag_update(typingctx, s, si, rmin, rarg, ri, nd):
    """Right-image winner bookkeeping: where s[si+k] < rmin[ri+k], rmin[ri+k] = s[si+k] and
    rarg[ri+k] = k (strictly smaller only: the first minimum in scan order is kept)."""
    if not _i16_arrays(s, rmin, rarg):
        return None

    def codegen(context, builder, sig, args):
        st = sig.args
        siv, riv, ndv = (_intp(context, builder, sig, args, i) for i in (1, 4, 5))

        def body(j0, n):
            vty = ir.VectorType(_I16, n)
            x = _vload(builder, _ptr(context, builder, st[0], args[0], [builder.add(siv, j0)]),
                       vty)
            pr = _ptr(context, builder, st[2], args[2], [builder.add(riv, j0)])
            pa = _ptr(context, builder, st[3], args[3], [builder.add(riv, j0)])
            r = _vload(builder, pr, vty)
            lt = builder.icmp_signed("<", x, r)
            _vstore(builder, builder.select(lt, x, r), pr)
            ks = builder.add(_splat(builder, builder.trunc(j0, _I16), vty),
                             ir.Constant(vty, list(range(n))))
            _vstore(builder, builder.select(lt, ks, _vload(builder, pa, vty)), pa)

        _chunked(builder, ndv, body)
        return context.get_dummy_value()

    return types.none(s, si, rmin, rarg, ri, nd), codegen


@intrinsic
def popcount16(typingctx, x):
    """Number of set bits of a uint64, as int16."""
    if x != types.uint64:
        return None

    def codegen(context, builder, sig, args):
        return builder.trunc(_call(builder, "llvm.ctpop.i64", args[0].type, [args[0]]), _I16)

    return types.int16(x), codegen


def _lock_ptr(context, builder, sig, args):
    return _ptr(context, builder, sig.args[0], args[0], [_intp(context, builder, sig, args, 1)])


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
