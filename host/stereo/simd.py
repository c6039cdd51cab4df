"""Explicit-width vector operations over the cost axis, as numba intrinsics.

Each intrinsic walks the ``nd`` cost indices of one pixel in chunks of 64 lanes, then tails of
32 and 16, of the arrays' element type (int16 or int32). Writing the
vector IR directly keeps LLVM's per-call runtime alias checks, horizontal reductions per chunk
and unpredictable branches out of the per-pixel path. Callers guarantee indices are in range.
"""
from __future__ import annotations

import platform

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

_TAIL = 16
_I32 = ir.IntType(32)
_I64 = ir.IntType(64)
X86 = platform.machine().lower() in ("x86_64", "amd64")


def _vector_bytes() -> int:
    """Bytes in one SIMD register of the CPU numba compiles for: 64 with AVX-512BW, 32 with
    AVX2, else 16 (SSE, NEON)."""
    from llvmlite import binding
    from numba import config
    if config.CPU_FEATURES:  # NUMBA_CPU_FEATURES, e.g. '+avx2,-avx512bw'
        on = {f[1:] for f in str(config.CPU_FEATURES).split(",") if f.startswith("+")}
    else:
        on = {k for k, v in binding.get_host_cpu_features().items() if v}
    return 64 if "avx512bw" in on else 32 if "avx2" in on else 16


LANES = _vector_bytes()  # lanes per chunk of the SGM kernels' disparity loops (sgm_simd)


def _ptr(context, builder, aryty, ary, inds):
    arr = context.make_array(aryty)(context, builder, ary)
    return cgutils.get_item_pointer(context, builder, aryty, arr, inds, wraparound=False)


def _vload(builder, ptr, vty):
    return builder.load(builder.bitcast(ptr, vty.as_pointer()), align=1)


def _vstore(builder, val, ptr):
    builder.store(val, builder.bitcast(ptr, val.type.as_pointer()), align=1)


def _call(builder, name, ret, args):
    fnty = ir.FunctionType(ret, [a.type for a in args])
    return builder.call(cgutils.get_or_insert_function(builder.module, fnty, name), args)


def _splat(builder, scalar, vty):
    v = builder.insert_element(ir.Constant(vty, ir.Undefined), scalar, ir.Constant(_I32, 0))
    return builder.shuffle_vector(v, ir.Constant(vty, ir.Undefined),
                                  ir.Constant(ir.VectorType(_I32, vty.count), None))


def _smin(builder, a, b):
    return builder.select(builder.icmp_signed("<", a, b), a, b)


def _reduce_min(builder, vec):
    name = f"llvm.vector.reduce.smin.v{vec.type.count}i{vec.type.element.width}"
    return _call(builder, name, vec.type.element, [vec])


def _absdiff_u8(builder, scalar, vec):
    """|scalar - vec| lane-wise on uint8 (exact), as <n x i8>."""
    splat = _splat(builder, scalar, vec.type)
    gt = builder.icmp_unsigned(">", splat, vec)
    return builder.sub(builder.select(gt, splat, vec), builder.select(gt, vec, splat))


def _chunked(builder, nd, body, widest=64):
    """Emit body(j0, lanes) over j0 < nd (a multiple of 16): steps of ``widest`` lanes, then
    tails of half as many, down to 16."""
    top = builder.and_(nd, ir.Constant(nd.type, -widest))
    with cgutils.for_range_slice(builder, ir.Constant(nd.type, 0), top,
                                 ir.Constant(nd.type, widest)) as (j0, _):
        body(j0, widest)
    n = widest // 2
    while n >= _TAIL:
        nxt = builder.add(top, builder.and_(builder.sub(nd, top), ir.Constant(nd.type, n)))
        with builder.if_then(builder.icmp_signed("<", top, nxt)):
            body(top, n)
        top, n = nxt, n // 2


def _fold16(builder, vec):
    """Lane-wise min of a 16/32/64-lane vector folded to 16 lanes."""
    while vec.type.count > _TAIL:
        half = vec.type.count // 2
        lo = builder.shuffle_vector(vec, vec, ir.Constant(ir.VectorType(_I32, half),
                                                          list(range(half))))
        hi = builder.shuffle_vector(vec, vec, ir.Constant(ir.VectorType(_I32, half),
                                                          list(range(half, 2 * half))))
        vec = _smin(builder, lo, hi)
    return vec


def _acc_ok(vs, sad) -> bool:
    return (isinstance(vs, types.Array) and isinstance(sad, types.Array) and vs.ndim == 2
            and sad.ndim == 1 and vs.dtype == sad.dtype and vs.dtype in (types.int16, types.int32))


def _u8_arrays(*tys) -> bool:
    return all(isinstance(t, types.Array) and t.ndim == 1 and t.dtype == types.uint8
               for t in tys)


def _ix(context, builder, sig, args, i):
    return context.cast(builder, args[i], sig.args[i], types.intp)


@intrinsic
def slide_all(typingctx, vs, ci, cu, sad, pr, ya, ys, b, a, s, nd):
    """One column step for all nd cost indices j; returns min_j of the new sad:

        vs[ci, j] += |a - pr[ya, b+j]| - |s - pr[ys, b+j]|   (vertical window slides down)
        sad[j]    += vs[ci, j] - vs[cu, j]                   (horizontal window slides right)
    """
    if not _acc_ok(vs, sad) or pr.dtype != types.uint8 or a != types.uint8 or s != types.uint8:
        return None
    acc = vs.dtype

    def codegen(context, builder, sig, args):
        aty = context.get_value_type(acc)
        st = sig.args
        ndv = _ix(context, builder, sig, args, 10)
        civ, cuv = _ix(context, builder, sig, args, 1), _ix(context, builder, sig, args, 2)
        yav, ysv = _ix(context, builder, sig, args, 5), _ix(context, builder, sig, args, 6)
        bv = _ix(context, builder, sig, args, 7)
        top = ir.Constant(aty, (1 << (aty.width - 1)) - 1)
        best = cgutils.alloca_once_value(builder, _splat(builder, top, ir.VectorType(aty, _TAIL)))

        def body(j0, n):
            vty, bty = ir.VectorType(aty, n), ir.VectorType(ir.IntType(8), n)
            bj = builder.add(bv, j0)
            ra = _vload(builder, _ptr(context, builder, st[4], args[4], [yav, bj]), bty)
            rs = _vload(builder, _ptr(context, builder, st[4], args[4], [ysv, bj]), bty)
            # prefiltered values are <= 126, so both differences and their difference fit i8
            dd = builder.sext(builder.sub(_absdiff_u8(builder, args[8], ra),
                                          _absdiff_u8(builder, args[9], rs)), vty)
            pv = _ptr(context, builder, st[0], args[0], [civ, j0])
            pu = _ptr(context, builder, st[0], args[0], [cuv, j0])
            ps = _ptr(context, builder, st[3], args[3], [j0])
            v = builder.add(_vload(builder, pv, vty), dd)
            _vstore(builder, v, pv)
            t = builder.add(_vload(builder, ps, vty), builder.sub(v, _vload(builder, pu, vty)))
            _vstore(builder, t, ps)
            builder.store(_smin(builder, builder.load(best), _fold16(builder, t)), best)

        _chunked(builder, ndv, body)
        return _reduce_min(builder, builder.load(best))

    return acc(vs, ci, cu, sad, pr, ya, ys, b, a, s, nd), codegen


@intrinsic
def step_all(typingctx, vs, ci, cu, sad, nd):
    """sad[j] += vs[ci, j] - vs[cu, j] for all nd cost indices; returns min_j sad[j]."""
    if not _acc_ok(vs, sad):
        return None
    acc = vs.dtype

    def codegen(context, builder, sig, args):
        aty = context.get_value_type(acc)
        st = sig.args
        ndv = _ix(context, builder, sig, args, 4)
        civ, cuv = _ix(context, builder, sig, args, 1), _ix(context, builder, sig, args, 2)
        top = ir.Constant(aty, (1 << (aty.width - 1)) - 1)
        best = cgutils.alloca_once_value(builder, _splat(builder, top, ir.VectorType(aty, _TAIL)))

        def body(j0, n):
            vty = ir.VectorType(aty, n)
            pv = _ptr(context, builder, st[0], args[0], [civ, j0])
            pu = _ptr(context, builder, st[0], args[0], [cuv, j0])
            ps = _ptr(context, builder, st[3], args[3], [j0])
            t = builder.add(_vload(builder, ps, vty),
                            builder.sub(_vload(builder, pv, vty), _vload(builder, pu, vty)))
            _vstore(builder, t, ps)
            builder.store(_smin(builder, builder.load(best), _fold16(builder, t)), best)

        _chunked(builder, ndv, body)
        return _reduce_min(builder, builder.load(best))

    return acc(vs, ci, cu, sad, nd), codegen


@intrinsic
def wta_all(typingctx, sad, nd, value, thr):
    """(smallest j with sad[j] == value or nd, number of j with sad[j] <= thr), j < nd."""
    if not (isinstance(sad, types.Array) and sad.ndim == 1 and value == sad.dtype
            and thr == sad.dtype and sad.dtype in (types.int16, types.int32)):
        return None
    ret = types.UniTuple(types.int64, 2)

    def codegen(context, builder, sig, args):
        aty = context.get_value_type(sad.dtype)
        ndv = _ix(context, builder, sig, args, 1)
        first = cgutils.alloca_once_value(builder, ndv)
        count = cgutils.alloca_once_value(builder, ir.Constant(_I64, 0))

        def body(j0, n):
            vty, mty = ir.VectorType(aty, n), ir.IntType(n)
            x = _vload(builder, _ptr(context, builder, sig.args[0], args[0], [j0]), vty)
            eq = builder.bitcast(builder.icmp_signed("==", x, _splat(builder, args[2], vty)), mty)
            le = builder.bitcast(builder.icmp_signed("<=", x, _splat(builder, args[3], vty)), mty)
            k = builder.zext(_call(builder, f"llvm.cttz.i{n}", mty,
                                   [eq, ir.Constant(ir.IntType(1), 0)]), _I64)
            cur = builder.load(first)
            hit = builder.and_(builder.icmp_unsigned("<", k, ir.Constant(_I64, n)),
                               builder.icmp_signed("==", cur, ndv))
            builder.store(builder.select(hit, builder.add(j0, k), cur), first)
            c = builder.zext(_call(builder, f"llvm.ctpop.i{n}", mty, [le]), _I64)
            builder.store(builder.add(builder.load(count), c), count)

        _chunked(builder, ndv, body)
        return context.make_tuple(builder, ret, [builder.load(first), builder.load(count)])

    return ret(sad, nd, value, thr), codegen
