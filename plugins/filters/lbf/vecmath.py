"""float64 ``exp(-y)`` and ``log1p(t)`` from multiplies and adds, so that Numba loops over them
vectorise (a libm call per element keeps a loop scalar; this machine's Numba has no SVML).

They serve the network's sigmoid and softplus on the CPU (:func:`.cpu._row_mlp`), whose
arguments are ``exp(-|a|)`` in (0, 1].

:func:`exp_neg64`
    ``exp(-y)`` for ``y >= 0``: ``y`` clamped at :data:`EXP_CLAMP` (so the result stays a
    normal float64, at least ``exp(-708) = 3.3e-308``), ``n = round(-y / ln 2)``, ``r = -y - n
    ln 2`` (Cody-Waite, ``ln 2`` in two parts, the first with trailing zero bits so that ``n *
    LN2_HI`` is exact) in ``[-ln2/2, ln2/2]``, the degree-13 Taylor polynomial (truncation below
    5e-18 relative) and ``2**n`` written into the exponent bits. A few float64 ulps (tested
    against ``math.exp``).
:func:`log1p64`
    ``log1p(t)`` for ``t`` in [0, 1]: ``u = 1 + t`` rounded, ``log(u) * t / (u - 1)`` (which
    cancels the rounding of ``u``; ``t`` itself where ``u`` rounds to 1), ``log(u)`` from ``u =
    2**k m`` with ``m`` in [sqrt(1/2), sqrt(2)] and ``log m = 2 atanh(s)``, ``s = (m - 1) / (m +
    1)``, ``|s| <= 0.172``, the odd series to ``s**23`` (truncation below 1e-18). A few float64
    ulps (tested against ``math.log1p``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from harness import kernels

#: largest argument of :func:`exp_neg64`: exp(-708) is still a normal float64
EXP_CLAMP = 708.0
_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01  # 0x3fe62e42fee00000: n * _LN2_HI exact for |n| < 2^11
_LN2_LO = 1.90821492927058770002e-10
_SQRT2 = 1.4142135623730951
_ROUND_SHIFT = 6755399441055744.0  # 1.5 * 2**52
_TAYLOR = tuple(1.0 / float(np.prod(np.arange(1, k + 1, dtype=np.float64))) for k in range(14))
_ATANH = tuple(1.0 / (2 * k + 1) for k in range(12))


@njit(cache=True, inline="always", error_model="numpy")
def exp_neg64(y):
    """``exp(-min(y, EXP_CLAMP))`` in float64 for ``y >= 0`` (not NaN); see the module notes."""
    x = -min(y, EXP_CLAMP)
    n = np.floor(x * _LOG2E + 0.5)
    r = (x - n * _LN2_HI) - n * _LN2_LO
    c = _TAYLOR
    p = c[13]
    p = p * r + c[12]
    p = p * r + c[11]
    p = p * r + c[10]
    p = p * r + c[9]
    p = p * r + c[8]
    p = p * r + c[7]
    p = p * r + c[6]
    p = p * r + c[5]
    p = p * r + c[4]
    p = p * r + c[3]
    p = p * r + c[2]
    p = p * r + c[1]
    p = p * r + c[0]
    # 2**n: n + 1.5 * 2**52 is exact and has n (two's complement) in its low mantissa bits, so
    # its bits + 1023 shifted left by 52 are the exponent field of 2**n (no float-to-integer
    # conversion, which AVX2 lacks for float64 and which would keep the loop scalar)
    bits = kernels.float64_bits_as_int64(n + _ROUND_SHIFT)
    return p * kernels.int64_bits_as_float64((bits + np.int64(1023)) << np.int64(52))


@njit(cache=True, inline="always", error_model="numpy")
def log1p64(t):
    """``log1p(t)`` in float64 for ``t`` in [0, 1]; see the module notes."""
    u = 1.0 + t
    big = u > _SQRT2
    m = u * 0.5 if big else u
    k = 1.0 if big else 0.0
    s = (m - 1.0) / (m + 1.0)
    z = s * s
    c = _ATANH
    q = c[11]
    q = q * z + c[10]
    q = q * z + c[9]
    q = q * z + c[8]
    q = q * z + c[7]
    q = q * z + c[6]
    q = q * z + c[5]
    q = q * z + c[4]
    q = q * z + c[3]
    q = q * z + c[2]
    q = q * z + c[1]
    q = q * z + c[0]
    log_u = k * _LN2_HI + (2.0 * s * q + k * _LN2_LO)
    d = u - 1.0
    return log_u * (t / d) if d > 0.0 else t
