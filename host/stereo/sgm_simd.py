"""Vector operations over the disparity axis for the SGM kernels (their locks and atomics:
atomics.py).

Arrays are 1-D (uint8 path costs, int16 sums) with the disparity axis contiguous; ``nd`` is a
multiple of 16 and each loop walks it in chunks of simd.LANES lanes (one register of the CPU's
widest vectors: 64 with AVX-512, 32 with AVX2), then 32/16-lane tails (simd._chunked). Callers
guarantee indices are in range.

The sums pixel_paths writes are in split order: each chunk of n disparities from j0 holds
those of even k - j0 first, then the odd ones (sum_pos), which is how a register of byte path
costs widens into 16-bit lanes without shuffles. The sums' readers here (add_argmin,
count_le, diag_update) know it; others index them with sum_pos.
"""
from __future__ import annotations

import numba as nb
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from .jit import C_ARITHMETIC
from .simd import LANES, X86, _call, _chunked, _ix, _u8_arrays, _ptr, _reduce_min, _splat, _vload, \
    _vstore

_I16 = ir.IntType(16)
_I32 = ir.IntType(32)


def _i16_arrays(*tys) -> bool:
    return all(isinstance(t, types.Array) and t.ndim == 1 and t.dtype == types.int16
               for t in tys)


def _i16(context, builder, sig, args, i):
    return context.cast(builder, args[i], sig.args[i], types.int16)


@nb.njit(inline="always", **C_ARITHMETIC)
def sum_pos(k: int, nd: int) -> int:
    """Where disparity k of a pixel's nd sums is (split order, see the module docstring)."""
    top = nd & -LANES
    j0, n = k & -LANES, LANES
    if k >= top:  # in a tail: its chunks are the bits of nd - top, widest first
        j0, n = top, LANES // 2
        while (nd - top) & n == 0 or k >= j0 + n:
            j0 += (nd - top) & n
            n //= 2
    r = k - j0
    return j0 + (r >> 1) + (r & 1) * (n >> 1)


def _split_labels(n):
    """Disparity offsets (from the chunk's j0) of an n-lane chunk of sums in split order."""
    return [2 * i for i in range(n // 2)] + [2 * i + 1 for i in range(n // 2)]


def _natural(builder, v):
    """A chunk of sums in split order put in disparity order."""
    n = v.type.count
    return builder.shuffle_vector(v, v, ir.Constant(ir.VectorType(_I32, n), [
        (k >> 1) + (k & 1) * (n >> 1) for k in range(n)]))


def _key_halves(builder, t, k0):
    """The int32 keys (t[i] << 16) | k of the n int16 lanes t of a chunk of sums from k0 in
    split order (0 <= t[i] < 2^15, k its disparity), as two n/2-lane vectors in no particular
    lane order: words of t and of their k interleaved within each 128-bit block, which x86
    does in one unpack per vector."""
    n = t.type.count
    k = builder.add(_splat(builder, k0, t.type), ir.Constant(t.type, _split_labels(n)))
    halves = []
    for part in (0, 4):
        idx = [i for blk in range(0, n, 8) for j in range(part, part + 4)
               for i in (blk + j, n + blk + j)]
        halves.append(builder.bitcast(builder.shuffle_vector(
            k, t, ir.Constant(ir.VectorType(_I32, n), idx)), ir.VectorType(_I32, n // 2)))
    return halves


@intrinsic
def add_argmin(typingctx, dst, di, src, si, nd):
    """dst[di+i] += src[si+i] for i < nd (src None: dst as it is); returns (m, first k
    holding m), m the minimum of the new values (sums in split order, 0 <= each < 2^15). One
    pass: the minimum of the keys (value << 16) | k, whose low half is then that k."""
    add = not isinstance(src, (types.NoneType, types.Omitted))
    if not (_i16_arrays(dst) and (not add or _i16_arrays(src))):
        return None
    ret = types.UniTuple(types.int64, 2)

    def codegen(context, builder, sig, args):
        st = sig.args
        div, siv, ndv = (_ix(context, builder, sig, args, i) for i in (1, 3, 4))
        i64 = ir.IntType(64)
        half = LANES // 2
        wide = ir.VectorType(_I32, half)
        best = cgutils.alloca_once_value(builder, ir.Constant(wide, [0x7FFFFFFF] * half))

        def body(j0, n):
            vty = ir.VectorType(_I16, n)
            pd = _ptr(context, builder, st[0], args[0], [builder.add(div, j0)])
            t = _vload(builder, pd, vty)
            if add:
                s = _vload(builder, _ptr(context, builder, st[2], args[2],
                                         [builder.add(siv, j0)]), vty)
                t = builder.add(t, s)
                _vstore(builder, t, pd)
            for key in _key_halves(builder, t, builder.trunc(j0, _I16)):
                if n < LANES:  # pad to the slot's lanes with keys that never win
                    pad = ir.Constant(ir.VectorType(_I32, half),
                                      list(range(n // 2)) + [n // 2] * (half - n // 2))
                    key = builder.shuffle_vector(key, ir.Constant(key.type, [0x7FFFFFFF] * (n // 2)),
                                                 pad)
                b = builder.load(best)
                builder.store(builder.select(builder.icmp_signed("<", key, b), key, b), best)

        _chunked(builder, ndv, body, LANES)
        low = builder.sext(_reduce_min(builder, builder.load(best)), i64)
        m = builder.ashr(low, ir.Constant(i64, 16))
        k = builder.and_(low, ir.Constant(i64, 0xFFFF))
        return context.make_tuple(builder, ret, [m, k])

    return ret(dst, di, src, si, nd), codegen


@intrinsic
def count_le(typingctx, s, si, nd, thr):
    """Number of k < nd with s[si+k] <= thr (any order)."""
    if not (_i16_arrays(s) and isinstance(thr, types.Integer)):
        return None

    def codegen(context, builder, sig, args):
        siv, ndv = (_ix(context, builder, sig, args, i) for i in (1, 2))
        thv = _i16(context, builder, sig, args, 3)
        i64 = ir.IntType(64)
        count = cgutils.alloca_once_value(builder, ir.Constant(i64, 0))

        def body(j0, n):
            vty, mty = ir.VectorType(_I16, n), ir.IntType(n)
            x = _vload(builder, _ptr(context, builder, sig.args[0], args[0],
                                     [builder.add(siv, j0)]), vty)
            le = builder.bitcast(builder.icmp_signed("<=", x, _splat(builder, thv, vty)), mty)
            c = builder.zext(_call(builder, f"llvm.ctpop.i{n}", mty, [le]), i64)
            builder.store(builder.add(builder.load(count), c), count)

        _chunked(builder, ndv, body, LANES)
        return builder.load(count)

    return types.int64(s, si, nd, thr), codegen


@intrinsic
def diag_update(typingctx, s, si, rmin, rarg, ri, nd):
    """Right-image winner bookkeeping: where S[k] < rmin[ri+k], rmin[ri+k] = S[k] and
    rarg[ri+k] = k (strictly smaller only: the first minimum in scan order is kept); S the
    sums from s[si] (split order)."""
    if not _i16_arrays(s, rmin, rarg):
        return None

    def codegen(context, builder, sig, args):
        st = sig.args
        siv, riv, ndv = (_ix(context, builder, sig, args, i) for i in (1, 4, 5))

        def body(j0, n):
            vty = ir.VectorType(_I16, n)
            x = _natural(builder, _vload(builder, _ptr(context, builder, st[0], args[0],
                                                       [builder.add(siv, j0)]), vty))
            pr = _ptr(context, builder, st[2], args[2], [builder.add(riv, j0)])
            pa = _ptr(context, builder, st[3], args[3], [builder.add(riv, j0)])
            r = _vload(builder, pr, vty)
            lt = builder.icmp_signed("<", x, r)
            _vstore(builder, builder.select(lt, x, r), pr)
            ks = builder.add(_splat(builder, builder.trunc(j0, _I16), vty),
                             ir.Constant(vty, list(range(n))))
            _vstore(builder, builder.select(lt, ks, _vload(builder, pa, vty)), pa)

        _chunked(builder, ndv, body, LANES)
        return context.get_dummy_value()

    return types.none(s, si, rmin, rarg, ri, nd), codegen


@intrinsic
def stream_copy(typingctx, dst, src, n):
    """dst[k] = src[k] for k < n (int16; n a multiple of 16, dst 32-byte aligned). On x86 the
    stores are non-temporal, then fenced: a parked row is read back much later or by the other
    thread, so writing it around the cache saves each line's read-for-ownership from memory."""
    if not _i16_arrays(dst, src):
        return None

    def codegen(context, builder, sig, args):
        st = sig.args
        nv = _ix(context, builder, sig, args, 2)
        vty = ir.VectorType(_I16, 16)
        nt = builder.module.add_metadata([ir.Constant(_I32, 1)])
        with cgutils.for_range_slice(builder, ir.Constant(nv.type, 0), nv,
                                     ir.Constant(nv.type, 16)) as (i, _):
            v = _vload(builder, _ptr(context, builder, st[1], args[1], [i]), vty)
            pd = builder.bitcast(_ptr(context, builder, st[0], args[0], [i]), vty.as_pointer())
            store = builder.store(v, pd, align=32)
            if X86:
                store.set_metadata("nontemporal", nt)
        if X86:
            _call(builder, "llvm.x86.sse.sfence", ir.VoidType(), [])
        return context.get_dummy_value()

    return types.none(dst, src, n), codegen


_UMIN = f"llvm.vector.reduce.umin.v{LANES}i8"
# Below 512-bit vectors a run's neighbours P[k-1], P[k+1] come cheaper from two unaligned loads
# than from shuffles across the register's 128-bit halves: so for every path of pixel_paths,
# the horizontal one too (its step reads the run the previous pixel just wrote, which an
# unaligned load does not get forwarded from the store, but the pass is bound by its
# operations, not by that wait). path_step's lone kept path is bound by that chain: it
# shuffles. The loads reach one byte before and after a run (after lbuf's last one:
# matcher._aligned allocates more than it returns); 255 is OR-ed over those lanes.
LOAD_NEIGHBOURS = LANES < 64


def _umin(builder, a, b):
    return builder.select(builder.icmp_unsigned("<", a, b), a, b)


def _step_chunk(context, builder, lbty, lbuf, c, meta, j0, n, nd, p1s, p1hi=None,
                loads=False):
    """L[k] for the n disparities from j0 of one path step (pixel_paths), stored at
    lbuf[oo + j0 + k]; meta = (po, oo, p2m, mprev): po, oo int64, p2m and mprev int64 (their
    low byte) or byte vectors (_bytes_of); nd: the run's length;
    p1hi: the step from P[k+1]'s own P1 (None: p1s, the step from P[k-1]'s, for both);
    loads: P[k-1] and P[k+1] loaded unaligned (LOAD_NEIGHBOURS)."""
    u8 = ir.IntType(8)
    vty = ir.VectorType(u8, n)
    po, oo, p2m, mp = meta
    p2m, mp = (_bytes_of(builder, v, n) for v in (p2m, mp))
    pj = builder.add(po, j0)

    def at(off):
        return _ptr(context, builder, lbty, lbuf, [off])
    pv = _vload(builder, at(pj), vty)
    if loads:  # P[k-1] and P[k+1] from memory, 255 OR-ed in beyond the run's ends
        first = builder.icmp_signed("==", j0, ir.Constant(j0.type, 0))
        last = builder.icmp_signed("==", builder.add(j0, ir.Constant(j0.type, n)), nd)
        lo = builder.or_(_vload(builder, at(builder.sub(pj, ir.Constant(pj.type, 1))), vty),
                         builder.select(first, ir.Constant(vty, [255] + [0] * (n - 1)),
                                        ir.Constant(vty, None)))
        hi = builder.or_(_vload(builder, at(builder.add(pj, ir.Constant(pj.type, 1))), vty),
                         builder.select(last, ir.Constant(vty, [0] * (n - 1) + [255]),
                                        ir.Constant(vty, None)))
    else:
        # P[k-1] and P[k+1] by shifting the chunk (loaded where it was stored, so a
        # just-written predecessor forwards) with the neighbouring element: 255 beyond
        # either end of the run (read inside it, then replaced)
        inner_lo = builder.icmp_signed(">", j0, ir.Constant(j0.type, 0))
        inner_hi = builder.icmp_signed("<", builder.add(j0, ir.Constant(j0.type, n)), nd)
        before = builder.load(at(builder.sub(pj, builder.zext(inner_lo, pj.type))))
        after = builder.load(at(builder.add(pj, builder.select(
            inner_hi, ir.Constant(pj.type, n), ir.Constant(pj.type, n - 1)))))
        before = builder.select(inner_lo, before, ir.Constant(u8, 255))
        after = builder.select(inner_hi, after, ir.Constant(u8, 255))
        lo = builder.shuffle_vector(pv, _splat(builder, before, vty), ir.Constant(
            ir.VectorType(_I32, n), [n] + list(range(n - 1))))
        hi = builder.shuffle_vector(pv, _splat(builder, after, vty), ir.Constant(
            ir.VectorType(_I32, n), list(range(1, n)) + [n]))
    sat = f"llvm.uadd.sat.v{n}i8"
    if p1hi is None:
        t = _call(builder, sat, vty, [_umin(builder, lo, hi), p1s])
    else:  # a ground step: one neighbour's P1 is cheaper
        t = _umin(builder, _call(builder, sat, vty, [lo, p1s]),
                  _call(builder, sat, vty, [hi, p1hi]))
    m = _umin(builder, _umin(builder, pv, t), p2m)
    L = builder.sub(builder.add(c, m), mp)
    _vstore(builder, L, at(builder.add(oo, j0)))
    return L


def _bytes_of(builder, v, n):
    """The n-byte vector of v: v's first n lanes if it is a byte vector, else the splat of
    int v's low byte."""
    if isinstance(v.type, ir.VectorType):
        if v.type.count == n:
            return v
        return builder.shuffle_vector(v, v, ir.Constant(ir.VectorType(_I32, n), list(range(n))))
    return _splat(builder, builder.trunc(v, ir.IntType(8)), ir.VectorType(ir.IntType(8), n))


def _rep_bytes(builder, v):
    """The LANES-byte vector of byte b from v = b * 0x01010101 (int64): a dword splat, which
    x86 loads straight from memory (vpbroadcastd) where v was just loaded, with no shuffle."""
    w = _splat(builder, builder.trunc(v, _I32), ir.VectorType(_I32, LANES // 4))
    return builder.bitcast(w, ir.VectorType(ir.IntType(8), LANES))


def _keep_min(builder, best, L, n):
    """best (a <LANES x i8> slot) = lane-wise min(best, L padded with 255 to LANES lanes)."""
    lw = L if n == LANES else builder.shuffle_vector(
        L, ir.Constant(L.type, [255] * n),
        ir.Constant(ir.VectorType(_I32, LANES), list(range(n)) + [n] * (LANES - n)))
    builder.store(_umin(builder, builder.load(best), lw), best)


@intrinsic
def path_step(typingctx, cost, ci, lbuf, po, oo, p2m, mprev, p1, nd):
    """One path step of one pixel (pixel_paths' for a single path, its meta as arguments):
    lbuf[oo+k] = L[k] for k < nd; returns min_k L[k]."""
    if not (_u8_arrays(cost, lbuf) and all(isinstance(t, types.Integer)
                                           for t in (ci, po, oo, p2m, mprev, p1, nd))):
        return None

    def codegen(context, builder, sig, args):
        st = sig.args
        u8 = ir.IntType(8)
        civ, pov, oov, p2v, mpv, ndv = (_ix(context, builder, sig, args, i)
                                        for i in (1, 3, 4, 5, 6, 8))
        p1v = context.cast(builder, args[7], st[7], types.uint8)
        best = cgutils.alloca_once_value(builder, ir.Constant(ir.VectorType(u8, LANES),
                                                              [255] * LANES))

        def body(j0, n):
            vty = ir.VectorType(u8, n)
            c = _vload(builder, _ptr(context, builder, st[0], args[0], [builder.add(civ, j0)]),
                       vty)
            L = _step_chunk(context, builder, st[2], args[2], c, (pov, oov, p2v, mpv), j0, n,
                            ndv, _splat(builder, p1v, vty))
            _keep_min(builder, best, L, n)

        _chunked(builder, ndv, body, LANES)
        low = _call(builder, _UMIN, u8, [builder.load(best)])
        return builder.zext(low, ir.IntType(64))

    return types.int64(cost, ci, lbuf, po, oo, p2m, mprev, p1, nd), codegen


@intrinsic
def pixel_paths(typingctx, cost, ci, lbuf, meta, npaths, p1, acc, ai, nd, mins, p1pair):
    """All path steps of one pixel (npaths 1, 2, 4, or 5: four and a fifth path's stored
    L) in one pass over the disparities:

        for path v < min(npaths, 4), (po, oo, q, m) = meta[4v : 4v+4] (meta: 17 ints; q
        and m bytes times 0x01010101: the step's P2 and the predecessor's minimum):
          L_v[k] = cost[ci+k] + min(P, min(P[-1] +sat a, P[+1] +sat b), m +sat q) - m,
          P = lbuf[po+k], (a, b) = (p1, p1) for v = 0 (horizontal), else p1pair
          lbuf[oo+k] = L_v[k];  mins[v] = (min_k L_v[k]) * 0x01010101  (uint32)
        acc[ai + sum_pos(k, nd)] = sum_v L_v[k] (+ lbuf[meta[16]+k] when npaths is 5)
        (int16, split order; not written when npaths is 1)

    Path costs are uint8 (the caller keeps every L <= 255; P beyond the run's ends is 255,
    and +p1 saturates), so one register holds LANES disparities. q and m come and go as
    replicated dwords so that each is one broadcast from memory (no shuffle), and the step's
    P2 term min(m + q, 255) one saturating add. The
    cost and the sum stay in registers across the paths. The sum widens without shuffles:
    each register of L, read as 16-bit words, adds to T (the even disparities' sum plus 256
    times the odd ones', mod 2^16) and, shifted right by 8, to O (the odd ones' sum); the
    even ones' are T - (O << 8), exact as every sum is below 2^15."""
    if not (_u8_arrays(cost, lbuf) and _i16_arrays(acc) and isinstance(mins, types.Array)
            and mins.ndim == 1 and mins.dtype == types.uint32
            and isinstance(meta, types.UniTuple) and meta.count == 17
            and isinstance(meta.dtype, types.Integer)
            and isinstance(p1pair, types.UniTuple) and p1pair.count == 2):
        return None

    def codegen(context, builder, sig, args):
        st = sig.args
        u8 = ir.IntType(8)
        civ, aiv, ndv = (_ix(context, builder, sig, args, i) for i in (1, 7, 8))
        npv = _ix(context, builder, sig, args, 4)
        ntwo = builder.icmp_signed(">", npv, ir.Constant(npv.type, 1))
        nmore = builder.icmp_signed(">", npv, ir.Constant(npv.type, 2))
        extra = builder.icmp_signed("==", npv, ir.Constant(npv.type, 5))
        p1v = context.cast(builder, args[5], st[5], types.uint8)
        p1lo, p1hi = (context.cast(builder, builder.extract_value(args[10], i), st[10].dtype,
                                   types.uint8) for i in range(2))
        meta_v = [context.cast(builder, builder.extract_value(args[3], i), st[3].dtype,
                               types.intp) for i in range(17)]
        for v in range(4):  # (q, m) as byte vectors: p2m = m +sat q, mprev = m
            qv, mvv = (_rep_bytes(builder, meta_v[4 * v + i]) for i in (2, 3))
            meta_v[4 * v + 2] = _call(builder, f"llvm.uadd.sat.v{LANES}i8", qv.type, [mvv, qv])
            meta_v[4 * v + 3] = mvv
        wide = ir.VectorType(u8, LANES)
        best = [cgutils.alloca_once_value(builder, ir.Constant(wide, [255] * LANES))
                for _ in range(4)]

        def lb(off, vty):
            return _vload(builder, _ptr(context, builder, st[2], args[2], [off]), vty)

        def body(j0, n, ground):  # ground: the pair's steps differ
            vty, hty = ir.VectorType(u8, n), ir.VectorType(_I16, n // 2)
            eight = ir.Constant(hty, [8] * (n // 2))
            c = _vload(builder, _ptr(context, builder, st[0], args[0], [builder.add(civ, j0)]),
                       vty)
            sums = [cgutils.alloca_once(builder, hty) for _ in range(2)]  # T, O
            p1s = _splat(builder, p1v, vty)
            p1pair = (_splat(builder, p1lo, vty), _splat(builder, p1hi, vty))

            def step(v):
                L = _step_chunk(context, builder, st[2], args[2], c, meta_v[4 * v:4 * v + 4],
                                j0, n, ndv, *((p1s,) if v == 0 else p1pair if ground
                                              else p1pair[:1]), loads=LOAD_NEIGHBOURS)
                _keep_min(builder, best[v], L, n)
                return L

            def add(*regs):  # T += the registers as words, O += their odd bytes
                for slot, f in zip(sums, (lambda w: w, lambda w: builder.lshr(w, eight))):
                    t = builder.load(slot)
                    for r in regs:
                        t = builder.add(t, f(builder.bitcast(r, hty)))
                    builder.store(t, slot)

            first = step(0)
            with builder.if_then(ntwo, likely=True):
                for slot in sums:
                    builder.store(ir.Constant(hty, None), slot)
                add(first, step(1))
                with builder.if_then(nmore, likely=True):
                    add(step(2), step(3))
                with builder.if_then(extra, likely=True):
                    add(lb(builder.add(meta_v[16], j0), vty))
                odd = builder.load(sums[1])
                even = builder.sub(builder.load(sums[0]), builder.shl(odd, eight))
                at = builder.add(aiv, j0)
                _vstore(builder, even, _ptr(context, builder, st[6], args[6], [at]))
                _vstore(builder, odd, _ptr(context, builder, st[6], args[6], [
                    builder.add(at, ir.Constant(at.type, n // 2))]))

        # p1pair's two steps equal (no ground step on this row): one saturating add per path
        with builder.if_else(builder.icmp_unsigned("==", p1lo, p1hi)) as (equal, unequal):
            with equal:
                _chunked(builder, ndv, lambda j0, n: body(j0, n, False), LANES)
            with unequal:
                _chunked(builder, ndv, lambda j0, n: body(j0, n, True), LANES)
        for v in range(4):
            def put(v=v):
                low = _call(builder, _UMIN, u8,
                            [builder.load(best[v])])
                builder.store(builder.mul(builder.zext(low, _I32), ir.Constant(_I32, 0x01010101)),
                              _ptr(context, builder, st[9], args[9], [ir.Constant(civ.type, v)]))
            if v == 0:
                put()
            else:
                with builder.if_then(nmore if v >= 2 else ntwo, likely=True):
                    put()
        return context.get_dummy_value()

    return types.none(cost, ci, lbuf, meta, npaths, p1, acc, ai, nd, mins, p1pair), codegen
