"""Mitsuba's microfacet distributions: GGX and Beckmann, anisotropic, Smith's separable masking.

``dist`` 0 = GGX, 1 = Beckmann. ``mf_d`` is the normal distribution D(m); ``mf_g1`` Smith's
single-direction masking (Beckmann by Walter et al.'s rational approximation, as Mitsuba);
``mf_sample`` draws a microfacet normal: the visible normals of GGX (Heitz 2018, stretched by
alpha_u, alpha_v), D(m) cos(theta_m) for Beckmann; ``mf_pdf`` is the density of that normal.
"""

from __future__ import annotations

import math

from numba import njit

from .vecmath import normalize


@njit(cache=True, error_model="numpy")
def mf_d(m, au, av, dist):
    """D(m) for a unit normal ``m`` in the local frame."""
    c = m[2]
    if c <= 0.0:
        return 0.0
    c2 = c * c
    x = m[0] / au
    y = m[1] / av
    if dist == 1:
        result = math.exp(-(x * x + y * y) / c2) / (math.pi * au * av * c2 * c2)
    else:
        q = x * x + y * y + c2
        result = 1.0 / (math.pi * au * av * q * q)
    return result if result * c > 1e-20 else 0.0


@njit(cache=True, error_model="numpy")
def mf_g1(v, m, au, av, dist):
    """Smith's G1(v, m) (0 where v sees the back of m)."""
    if (v[0] * m[0] + v[1] * m[1] + v[2] * m[2]) * v[2] <= 0.0:
        return 0.0
    xy = (au * v[0]) ** 2 + (av * v[1]) ** 2
    if xy == 0.0:
        return 1.0
    t2 = xy / (v[2] * v[2])
    if dist == 1:
        a = 1.0 / math.sqrt(t2)
        if a >= 1.6:
            return 1.0
        return (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)
    return 2.0 / (1.0 + math.sqrt(1.0 + t2))


@njit(cache=True, error_model="numpy", inline="always")
def mf_sample(wo, au, av, dist, u1, u2):
    """A microfacet normal for the viewing direction ``wo`` (``wo[2] > 0``)."""
    if dist == 1:
        phi = math.atan2(av * math.sin(2.0 * math.pi * u2), au * math.cos(2.0 * math.pi * u2))
        cp = math.cos(phi)
        sp = math.sin(phi)
        inv_a2 = cp * cp / (au * au) + sp * sp / (av * av)
        tan2 = -math.log(max(1.0 - u1, 1e-300)) / inv_a2
        ct = 1.0 / math.sqrt(1.0 + tan2)
        st = math.sqrt(max(1.0 - ct * ct, 0.0))
        return (st * cp, st * sp, ct)
    vh = normalize((au * wo[0], av * wo[1], wo[2]))
    lensq = vh[0] * vh[0] + vh[1] * vh[1]
    if lensq > 0.0:
        inv = 1.0 / math.sqrt(lensq)
        t1 = (-vh[1] * inv, vh[0] * inv, 0.0)
    else:
        t1 = (1.0, 0.0, 0.0)
    t2 = (vh[1] * t1[2] - vh[2] * t1[1], vh[2] * t1[0] - vh[0] * t1[2], vh[0] * t1[1] - vh[1] * t1[0])
    r = math.sqrt(u1)
    phi = 2.0 * math.pi * u2
    p1 = r * math.cos(phi)
    p2 = r * math.sin(phi)
    s = 0.5 * (1.0 + vh[2])
    p2 = (1.0 - s) * math.sqrt(max(1.0 - p1 * p1, 0.0)) + s * p2
    p3 = math.sqrt(max(1.0 - p1 * p1 - p2 * p2, 0.0))
    nh = (p1 * t1[0] + p2 * t2[0] + p3 * vh[0], p1 * t1[1] + p2 * t2[1] + p3 * vh[1],
          p1 * t1[2] + p2 * t2[2] + p3 * vh[2])
    return normalize((au * nh[0], av * nh[1], max(nh[2], 0.0)))


@njit(cache=True, error_model="numpy", inline="always")
def mf_pdf(wo, m, au, av, dist):
    """Density (over microfacet normals) with which :func:`mf_sample` draws ``m``."""
    d = mf_d(m, au, av, dist)
    if dist == 1:
        return d * m[2]
    if wo[2] <= 0.0:
        return 0.0
    return d * mf_g1(wo, m, au, av, dist) * abs(wo[0] * m[0] + wo[1] * m[1] + wo[2] * m[2]) / wo[2]
