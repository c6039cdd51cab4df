"""The census comparison with a margin as one vector operation (census.py's masked rows).

numba caches census.py's kernels keyed on that file only: after editing this one, touch
census.py (or delete __pycache__) so the cache is rebuilt.
"""
from __future__ import annotations

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from .sgm_simd import _intp, _u8_arrays
from .simd import _call, _ptr, _splat, _vload, _vstore

_USUB = "llvm.usub.sat.v64i8"  # saturating a - b: |a - b| = usub(a, b) | usub(b, a)


@intrinsic
def census_bits_masked(typingctx, byte, row, centre, srow, scentre, ro, co, t, bit, n):
    """byte[x] |= bit where row[ro+x] < centre[co+x] and |srow[ro+x] - scentre[co+x]| > t,
    for x < n rounded up to 64 (uint8 arrays; the caller pads them so that the rounded range
    is readable and writable; 0 <= t <= 255)."""
    if not (_u8_arrays(byte, row, centre, srow, scentre) and isinstance(bit, types.Integer)
            and isinstance(t, types.Integer)):
        return None

    def codegen(context, builder, sig, args):
        st = sig.args
        rov, cov, nv = (_intp(context, builder, sig, args, i) for i in (5, 6, 9))
        vty = ir.VectorType(ir.IntType(8), 64)
        bits = _splat(builder, context.cast(builder, args[8], st[8], types.uint8), vty)
        tv = _splat(builder, context.cast(builder, args[7], st[7], types.uint8), vty)
        zero = ir.Constant(vty, None)

        def load(i, off, x):
            return _vload(builder, _ptr(context, builder, st[i], args[i], [builder.add(off, x)]), vty)

        with cgutils.for_range_slice(builder, ir.Constant(nv.type, 0), nv,
                                     ir.Constant(nv.type, 64)) as (x, _):
            darker = builder.icmp_unsigned("<", load(1, rov, x), load(2, cov, x))
            s, c = load(3, rov, x), load(4, cov, x)
            diff = builder.or_(_call(builder, _USUB, vty, [s, c]), _call(builder, _USUB, vty, [c, s]))
            hit = builder.and_(darker, builder.icmp_unsigned(">", diff, tv))
            pb = _ptr(context, builder, st[0], args[0], [x])
            _vstore(builder, builder.or_(_vload(builder, pb, vty), builder.select(hit, bits, zero)), pb)
        return context.get_dummy_value()

    return types.none(byte, row, centre, srow, scentre, ro, co, t, bit, n), codegen
