"""The census transform's codes as byte planes, and their Hamming costs, as numba intrinsics:
per 64 pixels census.py's rows put each eight comparisons into a byte vector, stored as it is
(census_codes); cost_run XORs and counts them a plane at a time for the SGM kernels."""
from __future__ import annotations

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from .simd import LANES, _call, _chunked, _ix, _ptr, _splat, _u8_arrays, _vload, _vstore

_I32 = ir.IntType(32)
PLANES = 8  # byte planes of a census code (64 bits)
FEW_PLANES = 4  # a census of at most 32 comparisons (the sparse 9x7) keeps only these
_SAT = ("llvm.uadd.sat.v64i8", "llvm.usub.sat.v64i8")  # saturating a + b, a - b


def _census_codegen(masked: bool):
    """census_codes' code generator; masked: census_codes_masked's (args 7, 8, 9: the
    smoothed source, its base and the margin t)."""
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
            if masked:  # |s - sc| > t <=> s > sat(sc + t) or s < sat(sc - t), bounds made
                # on the bytes as uint8 (XOR 0x80), then compared signed as the bytes are
                flip = ir.Constant(vty, [0x80] * 64)
                scentre = builder.xor(load(7, sbv, c0, x0), flip)
                hi, lo = (builder.xor(_call(builder, f, vty, [scentre, tv]), flip) for f in _SAT)
            # one byte plane per trip, its eight comparisons unrolled: the loop body stays
            # small enough for the CPU's decoded-instruction cache (the 62 comparisons of a
            # 9x7 window unrolled did not, and decoding bound the loop)
            with cgutils.for_range(builder, groups) as loop:
                g = loop.index
                a = zero
                for b in range(8):
                    n = builder.add(builder.mul(g, ir.Constant(ncv.type, 8)),
                                    ir.Constant(ncv.type, b))
                    ok = builder.icmp_signed("<", n, ncv)
                    k = builder.add(builder.select(ok, n, last),  # a valid comparison,
                                    ir.Constant(ncv.type, 1))     # masked off
                    hit = builder.icmp_signed("<", load(0, bv, k, x0), centre)
                    if masked:  # and |smoothed neighbour - smoothed centre| > t
                        s = load(7, sbv, k, x0)
                        hit = builder.and_(hit, builder.or_(
                            builder.icmp_signed(">", s, hi), builder.icmp_signed("<", s, lo)))
                    bit = builder.select(ok, ir.Constant(u8, 1 << b), ir.Constant(u8, 0))
                    a = builder.or_(a, builder.select(hit, _splat(builder, bit, vty), zero))
                _store_plane(context, builder, a, g, x0, wv, args[5], st[5], args[6])
            planes = cgutils.unpack_tuple(builder, context.make_array(st[5])(
                context, builder, args[5]).shape)[0]
            with cgutils.for_range_slice(builder, groups, planes,  # both intp
                                         ir.Constant(ncv.type, 1)) as (g, _):
                _store_plane(context, builder, zero, g, x0, wv, args[5], st[5], args[6])
        return context.get_dummy_value()

    return codegen


def _store_plane(context, builder, v, g, x0, wv, out, outty, rev):
    """Byte g of code x0 + i (v[i]) at out[g, x0 + i] (rev: out[g, w - 1 - x0 - i])."""
    at = builder.select(rev, builder.sub(builder.sub(wv, x0), ir.Constant(x0.type, 64)), x0)
    flip = ir.Constant(ir.VectorType(_I32, 64), list(range(63, -1, -1)))
    v = builder.select(rev, builder.shuffle_vector(v, v, flip), v)
    _vstore(builder, v, _ptr(context, builder, outty, out, [g, at]))


def _planes(*tys) -> bool:
    """Each is byte planes: a 2-D C-contiguous uint8 array, [b, i] byte b of code i."""
    return all(isinstance(t, types.Array) and t.ndim == 2 and t.dtype == types.uint8
               and t.layout == "C" for t in tys)


def _census_types(src, offs, out, rev) -> bool:
    return (_u8_arrays(src) and isinstance(offs, types.Array) and offs.dtype == types.int64
            and _planes(out) and isinstance(rev, types.Boolean))


@intrinsic
def census_codes(typingctx, src, base, offs, ncmp, w, out, rev):
    """Code x for x < w, a multiple of 64: bit n set where src[base + offs[1 + n] + x] <
    src[base + offs[0] + x] as int8, n < ncmp <= 64 (uint8 src holding an image XOR 0x80,
    census.py's padded rows: its order as uint8, compared in one signed instruction on x86,
    where an unsigned compare takes two), as byte planes: its byte b into out[b, x] (uint8
    (planes, >= w), planes >= ncmp / 8, those past ncmp zero; rev: out[b, w - 1 - x]). Per 64
    pixels a loop over the planes, each plane's eight comparisons in a byte vector (in
    registers), stored as it is."""
    if not _census_types(src, offs, out, rev):
        return None
    return types.none(src, base, offs, ncmp, w, out, rev), _census_codegen(False)


@intrinsic
def census_codes_masked(typingctx, src, base, offs, ncmp, w, out, rev, ssrc, sbase, t):
    """census_codes with a margin: bit n also needs |ssrc[sbase + offs[1 + n] + x] -
    ssrc[sbase + offs[0] + x]| > t (ssrc uint8, the smoothed image XOR 0x80 laid out as src;
    0 <= t <= 255), one more load and two signed compares per comparison."""
    if not (_census_types(src, offs, out, rev) and _u8_arrays(ssrc)
            and isinstance(t, types.Integer)):
        return None
    return (types.none(src, base, offs, ncmp, w, out, rev, ssrc, sbase, t),
            _census_codegen(True))


@intrinsic
def cost_run(typingctx, left, li, right, base, out, oi, nd):
    """out[oi+k] = popcount(L ^ R[base+k]) for k < nd (census codes; out uint8), L the code
    li of ``left`` and R those of ``right``, both byte planes (census_codes'), FEW_PLANES or
    PLANES of them (left.shape[0]). Per chunk a XOR per plane against a broadcast byte of L
    and byte popcounts, summed: no 64-bit popcount to pack into bytes (LLVM's takes 30
    shuffles per 32 codes below AVX-512)."""
    if not (_planes(left, right) and _u8_arrays(out)):
        return None

    def codegen(context, builder, sig, args):
        st = sig.args
        u8 = ir.IntType(8)
        liv, bv, oiv, ndv = (_ix(context, builder, sig, args, i) for i in (1, 3, 5, 6))
        planes = cgutils.unpack_tuple(builder, context.make_array(st[0])(
            context, builder, args[0]).shape)[0]

        def run(count):  # the chunks with ``count`` planes, unrolled
            lbytes = [builder.load(_ptr(context, builder, st[0], args[0],
                                        [ir.Constant(liv.type, b), liv])) for b in range(count)]

            def body(j0, n):
                vty = ir.VectorType(u8, n)
                total = None
                for b in range(count):
                    x = _vload(builder, _ptr(context, builder, st[2], args[2],
                                             [ir.Constant(bv.type, b), builder.add(bv, j0)]), vty)
                    pc = _call(builder, f"llvm.ctpop.v{n}i8", vty,
                               [builder.xor(x, _splat(builder, lbytes[b], vty))])
                    total = pc if total is None else builder.add(total, pc)
                _vstore(builder, total,
                        _ptr(context, builder, st[4], args[4], [builder.add(oiv, j0)]))

            _chunked(builder, ndv, body, LANES)

        few = builder.icmp_signed("<=", planes, ir.Constant(planes.type, FEW_PLANES))
        with builder.if_else(few) as (then, otherwise):
            with then:
                run(FEW_PLANES)
            with otherwise:
                run(PLANES)
        return context.get_dummy_value()

    return types.none(left, li, right, base, out, oi, nd), codegen
