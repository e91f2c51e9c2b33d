"""A branch-free, vectorizable natural logarithm for positive, normal float32 values.

``x = 2**e * m`` with ``m`` in [sqrt(1/2), sqrt(2)) from the float's bits, then ``log m = 2
atanh(t)``, ``t = (m - 1) / (m + 1)``, by its odd series to ``t**11``. The series runs in
float64: absolute error below 1e-10 (``tests/test_kernels.py`` bounds it). Its float64 division
vectorises where the caller compiles with ``error_model="numpy"`` (the function is inlined into
its caller, with the caller's options).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from harness.kernels.bits import float32_bits_as_int32, int32_bits_as_float32
from harness.kernels.fastexp import LN2

SQRT_HALF_BITS = 0x3F3504F3  # bits of float32 sqrt(1/2)


@njit(inline="always", cache=True, fastmath=True)
def fast_log(x):
    """``log(x)`` for a positive, normal, finite float32 ``x``.

    Parameters
    ----------
    x : float32

    Returns
    -------
    float64
    """
    bits = float32_bits_as_int32(x)
    # shift the split point to sqrt(1/2) so that m lies in [sqrt(1/2), sqrt(2))
    e = np.int32(np.int32(bits - np.int32(SQRT_HALF_BITS)) >> np.int32(23))
    m = int32_bits_as_float32(np.int32(bits - np.int32(e << np.int32(23))))
    md = np.float64(m)
    t = (md - 1.0) / (md + 1.0)
    t2 = t * t
    p = 1.0 / 11.0
    p = p * t2 + 1.0 / 9.0
    p = p * t2 + 1.0 / 7.0
    p = p * t2 + 1.0 / 5.0
    p = p * t2 + 1.0 / 3.0
    p = p * t2 + 1.0
    return np.float64(e) * LN2 + 2.0 * t * p
