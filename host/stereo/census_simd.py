"""The census transform's bit packing as numba intrinsics (census.py's rows): per 64 pixels
the comparisons go into eight byte vectors, which three rounds of two-source shuffles turn into
64-bit codes, or which are stored as they are: byte planes (what sgm_simd.cost_run reads)."""
from __future__ import annotations

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from .simd import _call, _ix, _ptr, _splat, _u8_arrays, _vload, _vstore

_I16 = ir.IntType(16)
_I32 = ir.IntType(32)


def _zip(builder, a, b, lanes, half):
    """Lanes half*lanes/2 .. of a and b interleaved: (a[i], b[i]) for lanes/2 indices i from
    half * lanes / 2, as one lanes-lane vector (a two-source shuffle)."""
    n = lanes // 2
    idx = [k for i in range(half * n, half * n + n) for k in (i, lanes + i)]
    return builder.shuffle_vector(a, b, ir.Constant(ir.VectorType(_I32, lanes), idx))


_SAT = ("llvm.uadd.sat.v64i8", "llvm.usub.sat.v64i8")  # saturating a + b, a - b


def _census_codegen(masked: bool, planes: bool):
    """census_codes' code generator; masked: census_codes_masked's (args 7, 8, 9: the
    smoothed source, its base and the margin t); planes: out is byte planes."""
    def codegen(context, builder, sig, args):
        st = sig.args
        u8 = ir.IntType(8)
        bv, ncv, wv = (_ix(context, builder, sig, args, i) for i in (1, 3, 4))
        vty = ir.VectorType(u8, 64)
        zero = ir.Constant(vty, None)
        groups = builder.udiv(builder.add(ncv, ir.Constant(ncv.type, 7)),
                              ir.Constant(ncv.type, 8))
        last = builder.sub(ncv, ir.Constant(ncv.type, 1))
        if masked:
            sbv = _ix(context, builder, sig, args, 8)
            tv = _splat(builder, context.cast(builder, args[9], st[9], types.uint8), vty)

        def offs(n):  # offs[n]
            return builder.load(_ptr(context, builder, st[2], args[2], [n]))

        def load(i, b, n, x0):  # the 64 bytes of array arg i at b + offs[n] + x0
            return _vload(builder, _ptr(context, builder, st[i], args[i], [
                builder.add(builder.add(b, offs(n)), x0)]), vty)

        with cgutils.for_range_slice(builder, ir.Constant(wv.type, 0), wv,
                                     ir.Constant(wv.type, 64)) as (x0, _):
            c0 = ir.Constant(ncv.type, 0)
            centre = load(0, bv, c0, x0)
            if masked:  # |s - sc| > t <=> s > sat(sc + t) or s < sat(sc - t)
                scentre = load(7, sbv, c0, x0)
                hi, lo = (_call(builder, f, vty, [scentre, tv]) for f in _SAT)
            acc = []
            for g in range(8):
                slot = cgutils.alloca_once_value(builder, zero)
                with builder.if_then(builder.icmp_signed(">", groups, ir.Constant(ncv.type, g))):
                    a = zero
                    for b in range(8):
                        n = ir.Constant(ncv.type, 8 * g + b)
                        ok = builder.icmp_signed("<", n, ncv)
                        k = builder.add(builder.select(ok, n, last),  # a valid comparison,
                                        ir.Constant(ncv.type, 1))     # masked off
                        hit = builder.icmp_unsigned("<", load(0, bv, k, x0), centre)
                        if masked:  # and |smoothed neighbour - smoothed centre| > t
                            s = load(7, sbv, k, x0)
                            hit = builder.and_(hit, builder.or_(
                                builder.icmp_unsigned(">", s, hi), builder.icmp_unsigned("<", s, lo)))
                        bit = builder.select(ok, ir.Constant(u8, 1 << b), ir.Constant(u8, 0))
                        a = builder.or_(a, builder.select(hit, _splat(builder, bit, vty), zero))
                    builder.store(a, slot)
                acc.append(builder.load(slot))
            if planes:
                _store_planes(context, builder, acc, x0, wv, args[5], st[5], args[6])
            else:
                _store_codes(context, builder, acc, x0, wv, args[5], st[5], args[6])
        return context.get_dummy_value()

    return codegen


def _store_planes(context, builder, acc, x0, wv, out, outty, rev):
    """Byte g of code x0 + i (acc[g][i]) at out[g, x0 + i] (rev: out[g, w - 1 - x0 - i])."""
    at = builder.select(rev, builder.sub(builder.sub(wv, x0), ir.Constant(x0.type, 64)), x0)
    flip = ir.Constant(ir.VectorType(_I32, 64), list(range(63, -1, -1)))
    for g in range(8):
        v = builder.select(rev, builder.shuffle_vector(acc[g], acc[g], flip), acc[g])
        _vstore(builder, v, _ptr(context, builder, outty, out, [ir.Constant(x0.type, g), at]))


def _store_codes(context, builder, acc, x0, wv, out, outty, rev):
    """Code x0 + i = (acc[g][i])_g at out[x0 + i] (rev: out[w - 1 - x0 - i])."""
    i64 = ir.IntType(64)
    # bytes -> 16-bit pairs -> 32-bit quads -> 64-bit codes: code x = (acc[g][x])_g
    pairs = [_zip(builder, acc[g], acc[g + 1], 64, h) for g in (0, 2, 4, 6)
             for h in (0, 1)]  # [pair][half]: 32 pixels each, 2 bytes per pixel
    w16 = ir.VectorType(_I16, 32)
    pairs = [builder.bitcast(v, w16) for v in pairs]
    quads = [_zip(builder, pairs[2 * p + q // 2], pairs[2 * p + 2 + q // 2], 32, q % 2)
             for p in (0, 2) for q in range(4)]  # 16 pixels each, 4 bytes per pixel
    w32 = ir.VectorType(_I32, 16)
    quads = [builder.bitcast(v, w32) for v in quads]
    q8 = ir.VectorType(i64, 8)
    for c in range(8):  # 8 pixels each
        code = builder.bitcast(_zip(builder, quads[c // 2], quads[4 + c // 2], 16, c % 2),
                               q8)
        x = builder.add(x0, ir.Constant(x0.type, 8 * c))
        flip = builder.shuffle_vector(code, code, ir.Constant(ir.VectorType(_I32, 8),
                                                              list(range(7, -1, -1))))
        at = builder.select(rev, builder.sub(builder.sub(wv, x), ir.Constant(
            x.type, 8)), x)
        _vstore(builder, builder.select(rev, flip, code),
                _ptr(context, builder, outty, out, [at]))


def _planes(out) -> bool:
    """out is byte planes (2-D C-contiguous uint8, 8 rows) rather than codes (1-D uint64)."""
    return out.ndim == 2 and out.dtype == types.uint8 and out.layout == "C"


def _census_types(src, offs, out, rev) -> bool:
    return (_u8_arrays(src) and isinstance(offs, types.Array) and offs.dtype == types.int64
            and isinstance(out, types.Array)
            and (out.ndim == 1 and out.dtype == types.uint64 or _planes(out))
            and isinstance(rev, types.Boolean))


@intrinsic
def census_codes(typingctx, src, base, offs, ncmp, w, out, rev):
    """Code x for x < w, a multiple of 64: bit n set where src[base + offs[1 + n] + x] <
    src[base + offs[0] + x], n < ncmp <= 64 (uint8 src), into out[x] (uint64; rev: out[w - 1
    - x]), or with out uint8 (8, >= w) its byte b into out[b, x] (rev: out[b, w - 1 - x]).
    Per 64 pixels the comparisons go into eight byte vectors (one per 8 bits, in
    registers): stored as they are as planes, or turned into the 64 codes by three rounds
    of two-source shuffles."""
    if not _census_types(src, offs, out, rev):
        return None
    return (types.none(src, base, offs, ncmp, w, out, rev),
            _census_codegen(False, _planes(out)))


@intrinsic
def census_codes_masked(typingctx, src, base, offs, ncmp, w, out, rev, ssrc, sbase, t):
    """census_codes with a margin: bit n also needs |ssrc[sbase + offs[1 + n] + x] -
    ssrc[sbase + offs[0] + x]| > t (ssrc uint8, the smoothed image laid out as src; 0 <= t
    <= 255), one more pair of loads and a fused compare per comparison."""
    if not (_census_types(src, offs, out, rev) and _u8_arrays(ssrc)
            and isinstance(t, types.Integer)):
        return None
    return (types.none(src, base, offs, ncmp, w, out, rev, ssrc, sbase, t),
            _census_codegen(True, _planes(out)))

