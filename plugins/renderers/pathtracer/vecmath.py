"""Small 3-vector helpers on float tuples, inlined into the Numba kernels."""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, error_model="numpy")
def dot(a, b):
    """Dot product of two 3-tuples."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, error_model="numpy")
def cross(a, b):
    """Cross product of two 3-tuples."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True, error_model="numpy")
def normalize(a):
    """Unit vector along ``a``; (0, 0, 0) stays zero."""
    n = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    if n > 0.0:
        return (a[0] / n, a[1] / n, a[2] / n)
    return (0.0, 0.0, 0.0)


@njit(cache=True, error_model="numpy")
def onb(n):
    """Two unit tangents (t, b) completing unit ``n`` to a right-handed frame.

    Duff et al., "Building an orthonormal basis, revisited", JCGT 2017.
    """
    sign = 1.0 if n[2] >= 0.0 else -1.0
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    t = (1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0])
    s = (b, sign + n[1] * n[1] * a, -n[1])
    return t, s


@njit(cache=True, error_model="numpy")
def to_local(v, t, s, n):
    """Coordinates of ``v`` in the frame (t, s, n)."""
    return (dot(v, t), dot(v, s), dot(v, n))


@njit(cache=True, error_model="numpy")
def to_world(v, t, s, n):
    """World vector of local coordinates ``v`` in the frame (t, s, n)."""
    return (
        v[0] * t[0] + v[1] * s[0] + v[2] * n[0],
        v[0] * t[1] + v[1] * s[1] + v[2] * n[1],
        v[0] * t[2] + v[1] * s[2] + v[2] * n[2],
    )


@njit(cache=True, error_model="numpy")
def luminance(r, g, b):
    """Rec. 709 luminance of linear RGB."""
    return 0.2126 * r + 0.7152 * g + 0.0722 * b
