"""A branch-free, vectorizable ``2**-t`` for non-negative float32 ``t``.

Numba calls libm's scalar ``exp`` (no SVML here), which stops LLVM from vectorizing the
à-trous inner loop. :func:`exp2_minus` evaluates ``2**-t`` as ``2**-k * 2**r`` with ``k =
round(t)`` and ``r = k - t`` in [-1/2, 1/2] (exact in float32: ``k`` and ``t`` are within a
factor 2 of each other, or ``k = 0``), a degree-5 polynomial for ``2**r`` and the power of two
subtracted from the polynomial's exponent bits. The EAW weight ``h exp(-a)`` is ``2**-(a log2(e)
- log2(h))``: the caller folds ``log2(e)`` into its coefficients and ``-log2(h)`` into the
argument, so a weight costs no multiplication outside the polynomial (the arithmetic that
bounds the filter's speed, see the README).

The polynomial is ``1 + r q(r)`` with ``q`` interpolating ``(2**r - 1) / r`` at the 5 Chebyshev
nodes of [-1/2, 1/2] (close to the minimax polynomial): relative error below 5e-7 for ``t`` in
[0, ``T_MAX``] (the tests bound it; 2.6e-7 measured, float32 evaluation included); for ``t >
T_MAX`` the result is exactly 0 (the true value is below 2.4e-38). ``2**-0`` is exactly 1. Any
finite ``t >= 0`` is accepted: the argument is clamped first.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

LOG2E = 1.4426950408889634
LN2 = 0.6931471805599453
#: arguments above this give 0 (``2**-125`` times the polynomial, at least ``2**-0.5``, is still a
#: normal float32, so the power of two can go straight into the exponent bits)
T_MAX = 125.0


def _chebyshev_exp2(degree: int) -> tuple:
    """Monomial coefficients (lowest first) of ``1 + r q(r)``, where ``q`` interpolates ``(2**r -
    1) / r`` at the ``degree`` Chebyshev nodes of [-1/2, 1/2]: close to the minimax polynomial of
    ``2**r`` of that degree, and exactly 1 at ``r = 0``."""
    nodes = 0.5 * np.cos((2 * np.arange(degree) + 1) * np.pi / (2 * degree))
    return (1.0, *np.polynomial.polynomial.polyfit(nodes, np.expm1(nodes * LN2) / nodes, degree - 1))


C0, C1, C2, C3, C4, C5 = (np.float32(c) for c in _chebyshev_exp2(5))


@intrinsic
def int32_bits_as_float32(typingctx, bits):
    """Reinterpret the bits of an int32 as a float32 (LLVM ``bitcast``)."""
    if bits != types.int32:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.float32))

    return types.float32(types.int32), codegen


@intrinsic
def float32_bits_as_int32(typingctx, value):
    """Reinterpret the bits of a float32 as an int32 (LLVM ``bitcast``)."""
    if value != types.float32:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.int32))

    return types.int32(types.float32), codegen


@njit(inline="always", cache=True, fastmath=True)
def exp2_minus(t):
    """``2**-t`` for float32 ``t >= 0``, branch-free (see the module notes for its error).

    Parameters
    ----------
    t : float32
        A non-negative, finite argument; values above ``T_MAX`` give 0.

    Returns
    -------
    float32
    """
    under = t > np.float32(T_MAX)
    t = min(t, np.float32(T_MAX))
    k = np.int32(t + np.float32(0.5))  # round(t), t >= 0
    r = np.float32(k) - t
    p = C5
    p = p * r + C4
    p = p * r + C3
    p = p * r + C2
    p = p * r + C1
    p = p * r + C0
    scaled = int32_bits_as_float32(np.int32(float32_bits_as_int32(p) - (k << np.int32(23))))
    return np.float32(0.0) if under else scaled


@njit(cache=True, fastmath=True)
def exp2_minus_array(t):
    """:func:`exp2_minus` over a 1-D float32 array (for tests and error bounds)."""
    out = np.empty_like(t)
    for i in range(t.shape[0]):
        out[i] = exp2_minus(t[i])
    return out
