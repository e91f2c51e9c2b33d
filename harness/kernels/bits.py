"""Bit casts between float32 and int32 and between float64 and int64 inside Numba code (an LLVM
``bitcast``: no instruction).

The fast exponentials and logarithm build and read float32 exponent fields with them (and a
float64 exponential its float64 ones); a test of the exponent bits also tells a finite float32
from inf and NaN where ``fastmath`` folds ``math.isfinite`` away.
"""

from __future__ import annotations

from numba import types
from numba.extending import intrinsic


@intrinsic
def int32_bits_as_float32(typingctx, bits):
    """Reinterpret the 32 bits of an int32 as a float32.

    Parameters
    ----------
    bits : int32
        Only an int32 is accepted: cast a wider integer with ``np.int32`` first.

    Returns
    -------
    float32
    """
    if bits != types.int32:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.float32))

    return types.float32(types.int32), codegen


@intrinsic
def float32_bits_as_int32(typingctx, value):
    """Reinterpret the 32 bits of a float32 as an int32.

    Parameters
    ----------
    value : float32

    Returns
    -------
    int32
    """
    if value != types.float32:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.int32))

    return types.int32(types.float32), codegen


@intrinsic
def int64_bits_as_float64(typingctx, bits):
    """Reinterpret the 64 bits of an int64 as a float64.

    Parameters
    ----------
    bits : int64
        Only an int64 is accepted: cast a narrower integer with ``np.int64`` first.

    Returns
    -------
    float64
    """
    if bits != types.int64:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.float64))

    return types.float64(types.int64), codegen


@intrinsic
def float64_bits_as_int64(typingctx, value):
    """Reinterpret the 64 bits of a float64 as an int64.

    Parameters
    ----------
    value : float64

    Returns
    -------
    int64
    """
    if value != types.float64:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.int64))

    return types.int64(types.float64), codegen
