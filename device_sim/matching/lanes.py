"""Narrow integer operations for numba kernels.

numba promotes every integer binop to int64, so LLVM vectorises int16 loops with 8 lanes per
512-bit register instead of 32. These intrinsics keep the operand width (wrap-around semantics,
as the C code they mirror), letting the vectoriser use 16-bit lanes.
"""
from __future__ import annotations

from numba.core import types
from llvmlite import ir
from numba.extending import intrinsic


def _same_int(*tys) -> bool:
    return all(isinstance(t, types.Integer) for t in tys) and all(t == tys[0] for t in tys)


@intrinsic
def nadd(typingctx, a, b):
    """a + b in the operands' own width."""
    if _same_int(a, b):
        def codegen(context, builder, sig, args):
            return builder.add(args[0], args[1])
        return a(a, b), codegen
    return None


@intrinsic
def nsub(typingctx, a, b):
    """a - b in the operands' own width."""
    if _same_int(a, b):
        def codegen(context, builder, sig, args):
            return builder.sub(args[0], args[1])
        return a(a, b), codegen
    return None


@intrinsic
def nmin(typingctx, a, b):
    """Signed/unsigned minimum in the operands' own width."""
    if _same_int(a, b):
        def codegen(context, builder, sig, args):
            x, y = args
            lt = (builder.icmp_signed("<", x, y) if sig.args[0].signed
                  else builder.icmp_unsigned("<", x, y))
            return builder.select(lt, x, y)
        return a(a, b), codegen
    return None


@intrinsic
def absdiff_u8(typingctx, a, b, like):
    """|a - b| of two uint8 values, zero-extended to the type of ``like``."""
    if a == types.uint8 and b == types.uint8 and isinstance(like, types.Integer):
        def codegen(context, builder, sig, args):
            x, y = args[0], args[1]
            gt = builder.icmp_unsigned(">", x, y)
            hi = builder.select(gt, x, y)
            lo = builder.select(gt, y, x)
            return builder.zext(builder.sub(hi, lo), context.get_value_type(sig.return_type))
        return like(a, b, like), codegen
    return None


@intrinsic
def eq_select(typingctx, a, b, x, y):
    """x if a == b else y (a, b one integer type; x, y another)."""
    if _same_int(a, b) and _same_int(x, y):
        def codegen(context, builder, sig, args):
            return builder.select(builder.icmp_signed("==", args[0], args[1]), args[2], args[3])
        return x(a, b, x, y), codegen
    return None


@intrinsic
def le_count(typingctx, a, b):
    """1 if a <= b (signed) else 0, in the operands' width."""
    if _same_int(a, b):
        def codegen(context, builder, sig, args):
            c = builder.icmp_signed("<=", args[0], args[1])
            return builder.zext(c, context.get_value_type(sig.return_type))
        return a(a, b), codegen
    return None


@intrinsic
def cast_like(typingctx, value, like):
    """Integer ``value`` converted (truncated / sign-extended) to the type of ``like``."""
    if isinstance(value, types.Integer) and isinstance(like, types.Integer):
        def codegen(context, builder, sig, args):
            return context.cast(builder, args[0], sig.args[0], sig.return_type)
        return like(value, like), codegen
    return None


@intrinsic
def uidx(typingctx, value):
    """A non-negative int64 retyped as uint64: array indexing then skips the wraparound
    select for negative indices, which otherwise turns contiguous loads into gathers."""
    if isinstance(value, types.Integer):
        def codegen(context, builder, sig, args):
            return context.cast(builder, args[0], sig.args[0], types.uint64)
        return types.uint64(value), codegen
    return None


@intrinsic
def opaque(typingctx, value):
    """Return ``value`` unchanged through an empty inline-asm barrier.

    Used on row indices so LLVM cannot widen a runtime alias check to the whole outer loop
    (it would then always report a conflict and run the scalar loop)."""
    if isinstance(value, types.Integer):
        def codegen(context, builder, sig, args):
            ty = context.get_value_type(sig.args[0])
            fnty = ir.FunctionType(ty, [ty])
            return builder.asm(fnty, "", "=r,0", [args[0]], side_effect=False)
        return value(value), codegen
    return None


@intrinsic
def cdiv(typingctx, a, b):
    """C integer division (truncates toward zero) in the operands' width; b must be != 0."""
    if _same_int(a, b):
        def codegen(context, builder, sig, args):
            if sig.args[0].signed:
                return builder.sdiv(args[0], args[1])
            return builder.udiv(args[0], args[1])
        return a(a, b), codegen
    return None
