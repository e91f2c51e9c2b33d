"""Scalar helpers shared by every stage: luminance, kernel taps and edge-stopping weights.

All are ``@njit`` scalar functions; the CPU kernels inline them, the CUDA kernels call them as
device code.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: smallest denominator used anywhere a depth or luminance difference is divided
TINY = 1e-30
#: bounds of the à-trous weights' inputs, the same in both backends (the CPU's float32 pool
#: needs them to keep every exponent and sum finite): variances at most VAR_MAX (25 x VAR_MAX
#: stays finite), luminances within +-LUM_MAX and the luminance weight's ``1 / (sigma_l
#: sqrt(Var) + eps)`` at most INV_MAX (their product stays finite; such a tap weighs 0 anyway)
VAR_MAX = 1.0e36
LUM_MAX = 1.0e18
INV_MAX = 1.0e18
#: expneg evaluates (1 + x / 2^EXP_SQUARINGS)^(2^EXP_SQUARINGS)
EXP_SQUARINGS = 10
_EXP_SCALE = np.float32(1.0 / (1 << EXP_SQUARINGS))
#: expneg is exactly 0 below -EXP_CUT: exp(-16) = 1.1e-7 (a tap weighted that little changes a
#: result by less than 1e-6 of the centre's weight); a weight times the smallest kernel tap
#: (1/256), squared and times a variance down to 1e-19, stays a normal float
EXP_CUT = 16.0
_EXP_CUT = np.float32(EXP_CUT)
_Y_MIN = np.float32(1.0 - EXP_CUT / (1 << EXP_SQUARINGS))
_ONE = np.float32(1.0)
_ZERO = np.float32(0.0)


@njit(cache=True, inline="always")
def luminance(r, g, b):
    """Rec. 709 luminance of linear RGB."""
    return 0.2126 * r + 0.7152 * g + 0.0722 * b


@njit(cache=True, inline="always")
def b3_tap(k):
    """Weight of tap ``k`` in {-2..2} of the 1-D B3-spline kernel (1/16, 1/4, 3/8, 1/4, 1/16)."""
    a = abs(k)
    if a == 0:
        return 0.375
    if a == 1:
        return 0.25
    return 0.0625


@njit(cache=True, inline="always")
def gauss3_tap(k):
    """Weight of tap ``k`` in {-1, 0, 1} of the 1-D 3-tap Gaussian (1/4, 1/2, 1/4)."""
    return 0.5 if k == 0 else 0.25


@njit(cache=True, inline="always")
def depth_distance(zp, zq, gx, gy, dx, dy, sigma_z, depth_eps):
    """``|z_p - z_q| / (sigma_z |grad z(p) . (dx, dy)| + eps)`` with ``eps = depth_eps * z_p``.

    The depth weight of the paper is ``exp(-depth_distance)``. ``(dx, dy)`` is the offset
    ``q - p`` in pixels and ``(gx, gy)`` the depth gradient at ``p`` in depth units per pixel.
    """
    den = sigma_z * abs(gx * dx + gy * dy) + depth_eps * abs(zp) + TINY
    return abs(zp - zq) / den


@njit(cache=True, inline="always")
def expneg(x):
    """Branch-free, vectorizable approximation of ``exp(x)`` for ``x <= 0``, float32.

    ``(1 + x / 1024)^1024`` by 10 squarings for ``x > -EXP_CUT``, exactly 0 below: exactly 1
    at 0, monotone, relative error about ``x^2 / 2048`` (0.05% at -1, 0.8% at -4; where it
    grows the weight is negligible). Used for the edge-stopping weights so that the CPU loops
    vectorize without a vector math library. The cut keeps every intermediate power, and the
    products of a weight with kernel taps, itself and a variance, normal floats: a subnormal
    operand costs a microcode assist on x86 (the à-trous iterations ran 1.5-2x slower with
    subnormal weights). NaN-free for ``x = -inf``.
    """
    xf = np.float32(x)
    y = max(_ONE + xf * _EXP_SCALE, _Y_MIN)
    y *= y
    y *= y
    y *= y
    y *= y
    y *= y
    y *= y
    y *= y
    y *= y
    y *= y
    y *= y
    return y if xf > -_EXP_CUT else _ZERO


@njit(cache=True, inline="always")
def neg_log_series(d):
    """``-ln(d)`` for ``d`` in (0, 1] by its series in ``x = 1 - d`` up to ``x^4 / 4``, float32.

    The normal weight is evaluated as ``d^sigma_n = exp(-sigma_n * neg_log_series(d))`` inside
    the one vectorizable exponential of a tap. The exponent is short by less than
    ``sigma_n x^5 / 5``: with sigma_n = 128 a relative error of 8e-6 in the weight at
    ``d = 0.95`` (weight 1.4e-3) and 2.8e-4 at ``d = 0.9`` (weight 1.4e-6). ``d >= 1`` gives 0.
    Used by the à-trous weights and the 7x7 spatial variance.
    """
    x = max(_ONE - np.float32(d), _ZERO)
    x2 = x * x
    return x + np.float32(0.5) * x2 + np.float32(1.0 / 3.0) * x2 * x + np.float32(0.25) * x2 * x2
