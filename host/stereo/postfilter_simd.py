"""The speckle filter's per-pixel flags as a numba intrinsic (postfilter._row_flags): a register
of int16 disparities at a time, so that per pixel only vector compares run and the labelling
visits just the pixels where something happens."""
from __future__ import annotations

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from .simd import LANES, _ix, _ptr, _splat, _vload, _vstore

_I16 = ir.IntType(16)
_I8 = ir.IntType(8)
N = LANES // 2  # int16 lanes per register


def _far(builder, a, b, md):
    """|a - b| > md lane-wise, exactly for any int16 a, b: max - min fits uint16."""
    gt = builder.icmp_signed(">", a, b)
    return builder.icmp_unsigned(">", builder.sub(builder.select(gt, a, b), builder.select(gt, b, a)),
                                 md)


@intrinsic
def run_flags(typingctx, im, o, a, x0, x1, new_val, max_diff, flags):
    """flags[x] for x from x0 (>= 1) in whole registers while they end at or before x1 (x0 <=
    x1 <= w - 1): bit 0 a run starts at x, bit 1 one ends at x, bit 2 (a >= 0, the row above's flat
    index) x joins the pixel above and is the first of its stretch of joins or a run start in
    either row; im int16 (flat), the row at o; 0 <= max_diff <= 65535. Returns the first x not
    done."""
    if not (isinstance(im, types.Array) and im.dtype == types.int16 and im.ndim == 1
            and isinstance(flags, types.Array) and flags.dtype == types.uint8 and flags.ndim == 1):
        return None

    def codegen(context, builder, sig, args):
        st = sig.args
        ov, av, x0v, x1v = (_ix(context, builder, sig, args, i) for i in (1, 2, 3, 4))
        vty, bty = ir.VectorType(_I16, N), ir.VectorType(_I8, N)
        nv = _splat(builder, builder.trunc(_ix(context, builder, sig, args, 5), _I16), vty)
        md = _splat(builder, builder.trunc(_ix(context, builder, sig, args, 6), _I16), vty)
        span = builder.sub(x1v, x0v)
        end = builder.sub(x1v, builder.srem(span, ir.Constant(span.type, N)))  # whole registers

        def load(base, x, off=0):
            return _vload(builder, _ptr(context, builder, st[0], args[0], [
                builder.add(builder.add(base, x), ir.Constant(x.type, off))]), vty)

        def bits(*masks):
            out = ir.Constant(bty, None)
            for b, m in enumerate(masks):
                out = builder.or_(out, builder.shl(builder.zext(m, bty), ir.Constant(bty, [b] * N)))
            return out

        def loop(above):
            with cgutils.for_range_slice(builder, x0v, end, ir.Constant(x0v.type, N)) as (x, _):
                v, p, n = load(ov, x), load(ov, x, -1), load(ov, x, 1)
                ok, pk = builder.icmp_signed("!=", v, nv), builder.icmp_signed("!=", p, nv)
                s = builder.and_(ok, builder.or_(builder.not_(pk), _far(builder, v, p, md)))
                e = builder.and_(ok, builder.or_(builder.icmp_signed("==", n, nv),
                                                 _far(builder, n, v, md)))
                masks = [s, e, ir.Constant(ok.type, None)]
                if above:
                    u, q = load(av, x), load(av, x, -1)
                    uk, qk = builder.icmp_signed("!=", u, nv), builder.icmp_signed("!=", q, nv)
                    j = builder.and_(builder.and_(ok, uk), builder.not_(_far(builder, v, u, md)))
                    jp = builder.and_(builder.and_(pk, qk), builder.not_(_far(builder, p, q, md)))
                    su = builder.and_(uk, builder.or_(builder.not_(qk), _far(builder, u, q, md)))
                    masks[2] = builder.and_(j, builder.or_(builder.or_(builder.not_(jp), s), su))
                _vstore(builder, bits(*masks), _ptr(context, builder, st[7], args[7], [x]))

        with builder.if_else(builder.icmp_signed(">=", av, ir.Constant(av.type, 0))) as (yes, no):
            with yes:
                loop(True)
            with no:
                loop(False)
        return end

    return types.intp(im, o, a, x0, x1, new_val, max_diff, flags), codegen
