"""Exponentials in float32 from multiplies and adds only, so that Numba loops over them vectorise.

This machine's Numba has no SVML: a libm ``exp`` per element keeps a loop scalar. Both functions
split the argument into an integer power of two, written straight into the float32 exponent
bits, and a remainder in ``[-1/2, 1/2]`` (in units of ``ln 2`` or of 1) evaluated by a short
polynomial. They are ``@njit(inline="always")``: they compile into the loop that calls them,
with the caller's ``fastmath`` and error model.

:func:`exp_neg`
    ``exp(-d)``: ``n = round(-d / ln 2)``, ``r = -d - n ln 2`` (Cody-Waite, two constants) in
    ``[-ln2/2, ln2/2]``, ``p`` the degree-7 Taylor polynomial (truncation error below 5e-9
    relative). Relative error: a few float32 ulps (measured < 3e-7 against float64 ``exp`` on
    ``[0, 87]``, ``tests/test_kernels.py``). ``d`` is clamped at ``EXP_NEG_CLAMP`` = 87, so the
    result is at least ``exp(-87) = 1.6e-38`` (a normal float32) and never 0 for finite ``d``;
    ``d`` must not be NaN (callers pass sanitised values).
:func:`exp2_minus`
    ``2**-t``: ``k = round(t)``, ``r = k - t`` in [-1/2, 1/2] (exact in float32: ``k`` and ``t``
    are within a factor 2 of each other, or ``k = 0``), a degree-5 polynomial for ``2**r`` and
    the power of two subtracted from the polynomial's exponent bits. The polynomial is ``1 + r
    q(r)`` with ``q`` interpolating ``(2**r - 1) / r`` at the 5 Chebyshev nodes of [-1/2, 1/2]
    (close to the minimax polynomial): relative error below 5e-7 for ``t`` in [0, ``T_MAX``]
    (2.6e-7 measured, float32 evaluation included); for ``t > T_MAX`` the result is exactly 0
    (the true value is below 2.4e-38). ``2**-0`` is exactly 1. Any finite ``t >= 0`` is
    accepted: the argument is clamped first. A weight ``h exp(-a)`` is ``2**-(a log2(e) -
    log2(h))``: a caller that folds ``LOG2E`` into its coefficients and ``-log2(h)`` into the
    argument pays no multiplication outside the polynomial.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from harness.kernels.bits import float32_bits_as_int32, int32_bits_as_float32

LOG2E = 1.4426950408889634
LN2 = 0.6931471805599453

#: largest argument of :func:`exp_neg`: exp(-87) is still a normal float32
EXP_NEG_CLAMP = 87.0
_LOG2E = np.float32(LOG2E)
_LN2_HI = np.float32(0.693359375)  # exact in float32: n * _LN2_HI is exact for |n| < 2^15
_LN2_LO = np.float32(-2.12194440e-4)
_HALF = np.float32(0.5)
_ONE = np.float32(1.0)
_T2 = np.float32(1.0 / 2.0)
_T3 = np.float32(1.0 / 6.0)
_T4 = np.float32(1.0 / 24.0)
_T5 = np.float32(1.0 / 120.0)
_T6 = np.float32(1.0 / 720.0)
_T7 = np.float32(1.0 / 5040.0)

#: arguments of :func:`exp2_minus` above this give 0 (``2**-125`` times the polynomial, at least
#: ``2**-0.5``, is still a normal float32, so the power of two can go straight into the exponent
#: bits)
T_MAX = 125.0


def _chebyshev_exp2(degree: int) -> tuple:
    """Monomial coefficients (lowest first) of ``1 + r q(r)``, where ``q`` interpolates ``(2**r -
    1) / r`` at the ``degree`` Chebyshev nodes of [-1/2, 1/2]: close to the minimax polynomial of
    ``2**r`` of that degree, and exactly 1 at ``r = 0``."""
    nodes = 0.5 * np.cos((2 * np.arange(degree) + 1) * np.pi / (2 * degree))
    return (1.0, *np.polynomial.polynomial.polyfit(nodes, np.expm1(nodes * LN2) / nodes, degree - 1))


_C0, _C1, _C2, _C3, _C4, _C5 = (np.float32(c) for c in _chebyshev_exp2(5))


@njit(cache=True, fastmath=True, inline="always")
def exp_neg(d):
    """``exp(-min(d, 87))`` in float32 (see the module notes for its error).

    Parameters
    ----------
    d : float32
        A non-negative argument, not NaN.

    Returns
    -------
    float32
        At least ``exp(-87)``, never 0.
    """
    x = -min(d, np.float32(EXP_NEG_CLAMP))
    n = np.floor(x * _LOG2E + _HALF)
    r = (x - n * _LN2_HI) - n * _LN2_LO
    p = _ONE + r * (_ONE + r * (_T2 + r * (_T3 + r * (_T4 + r * (_T5 + r * (_T6 + r * _T7))))))
    return p * int32_bits_as_float32(np.int32((np.int32(n) + np.int32(127)) << np.int32(23)))


@njit(cache=True, fastmath=True, inline="always")
def exp2_minus(t):
    """``2**-t``, branch-free (see the module notes for its error).

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
    p = _C5
    p = p * r + _C4
    p = p * r + _C3
    p = p * r + _C2
    p = p * r + _C1
    p = p * r + _C0
    scaled = int32_bits_as_float32(np.int32(float32_bits_as_int32(p) - (k << np.int32(23))))
    return np.float32(0.0) if under else scaled
