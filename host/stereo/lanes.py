"""Narrow integer operations for numba kernels.

numba promotes every integer binop to int64, so LLVM vectorises int16 loops with 8 lanes per
512-bit register instead of 32. These intrinsics keep the operand width (wrap-around semantics,
as the C code they mirror), letting the vectoriser use 16-bit lanes.
"""
from __future__ import annotations

from typing import Any, Callable, Concatenate, ParamSpec, cast

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic as numba_intrinsic

_P = ParamSpec("_P")


def intrinsic(typer: Callable[Concatenate[Any, _P], object]) -> Callable[_P, Any]:
    """``numba.extending.intrinsic``, typed as jitted code calls the result: without the typing
    context (numba passes it), returning a value of the type ``typer`` picks when compiling."""
    return cast("Callable[_P, Any]", numba_intrinsic(typer))


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
def cdiv(typingctx, a, b):
    """C integer division (truncates toward zero) in the operands' width; b must be != 0."""
    if _same_int(a, b):
        def codegen(context, builder, sig, args):
            if sig.args[0].signed:
                return builder.sdiv(args[0], args[1])
            return builder.udiv(args[0], args[1])
        return a(a, b), codegen
    return None


def _bit_count(value, name: str, *flags: int):
    """(signature, codegen) of the LLVM bit-counting intrinsic ``name`` on a uint64 (flags: its
    i1 arguments after the value)."""
    if not isinstance(value, types.Integer):
        return None

    def codegen(context, builder, sig, args):
        v = context.cast(builder, args[0], sig.args[0], types.uint64)
        more = [ir.Constant(ir.IntType(1), f) for f in flags]
        fnty = ir.FunctionType(v.type, [v.type] + [f.type for f in more])
        return builder.call(cgutils.get_or_insert_function(builder.module, fnty, name), [v, *more])
    return types.uint64(value), codegen


@intrinsic
def ctz(typingctx, value):
    """Trailing zero bits of a non-zero uint64 (one tzcnt / bsf)."""
    return _bit_count(value, "llvm.cttz.i64", 1)  # 1: zero is undefined


@intrinsic
def popcount(typingctx, value):
    """Set bits of a uint64 (one popcnt)."""
    return _bit_count(value, "llvm.ctpop.i64")
