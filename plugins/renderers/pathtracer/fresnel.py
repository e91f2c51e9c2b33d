"""Fresnel reflectance of dielectric and conductor interfaces (unpolarised)."""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, error_model="numpy")
def dielectric(cos_i, eta):
    """Reflectance for ``cos_i >= 0`` on the side of index 1, ``eta`` = index ratio (transmitted / incident)."""
    sin_t2 = (1.0 - cos_i * cos_i) / (eta * eta)
    if sin_t2 >= 1.0:
        return 1.0
    cos_t = math.sqrt(1.0 - sin_t2)
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return 0.5 * (rs * rs + rp * rp)


@njit(cache=True, error_model="numpy")
def dielectric_signed(cos_i, eta):
    """(F, cos_t, eta_it) for a signed ``cos_i``: from below (``cos_i < 0``) the ratio is ``1 / eta``.

    ``cos_t`` is the cosine of the refracted direction with the sign opposite to ``cos_i``;
    ``eta_it`` the ratio (transmitted / incident) on the side of incidence.
    """
    eta_it = eta if cos_i >= 0.0 else 1.0 / eta
    c = abs(cos_i)
    f = dielectric(c, eta_it)
    sin_t2 = (1.0 - c * c) / (eta_it * eta_it)
    cos_t = math.sqrt(max(1.0 - sin_t2, 0.0))
    return f, (-cos_t if cos_i >= 0.0 else cos_t), eta_it


@njit(cache=True, error_model="numpy")
def conductor(cos_i, eta, k):
    """Reflectance of a conductor of complex relative index ``eta + i k`` at ``cos_i`` in [0, 1].

    The exact unpolarised formula (as in Moeller, "Optics", 1988, which Mitsuba follows).
    """
    c2 = cos_i * cos_i
    s2 = 1.0 - c2
    s4 = s2 * s2
    t1 = eta * eta - k * k - s2
    a2pb2 = math.sqrt(max(t1 * t1 + 4.0 * k * k * eta * eta, 0.0))
    a = math.sqrt(max(0.5 * (a2pb2 + t1), 0.0))
    term1 = a2pb2 + c2
    term2 = 2.0 * cos_i * a
    rs = (term1 - term2) / (term1 + term2) if term1 + term2 > 0.0 else 1.0
    term3 = a2pb2 * c2 + s4
    term4 = term2 * s2
    rp = rs * (term3 - term4) / (term3 + term4) if term3 + term4 > 0.0 else rs
    return 0.5 * (rs + rp)


@njit(cache=True, error_model="numpy", inline="always")
def conductor_rgb(cos_i, nf, node, col_eta, col_k):
    """Per-channel :func:`conductor` of the (eta, k) columns of ``nf[node]``."""
    return (conductor(cos_i, nf[node, col_eta], nf[node, col_k]),
            conductor(cos_i, nf[node, col_eta + 1], nf[node, col_k + 1]),
            conductor(cos_i, nf[node, col_eta + 2], nf[node, col_k + 2]))
