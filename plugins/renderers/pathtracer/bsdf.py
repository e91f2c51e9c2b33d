"""Surface scattering of the scene model's materials, in the local shading frame (z = normal).

Kinds (``harness.scene.MATERIAL_KINDS`` order): 0 diffuse (Lambert), 1 conductor (GGX microfacet
with Schlick Fresnel of normal reflectance ``specular``), 2 plastic (Lambertian base under a GGX
coat: ``f = F D G / (4 cos_o cos_i) + (1 - F(cos_o)) albedo / pi``, a simple energy-bounded
layering without internal reflections), 3 dielectric (smooth glass, exact Fresnel; radiance is
scaled by ``(eta_i / eta_t)^2`` on refraction), 4 mirror (perfect specular reflection, reflectance 1).

The GGX distribution uses Smith's height-correlated masking-shadowing and is sampled with the
distribution of visible normals (Heitz, "Sampling the GGX distribution of visible normals",
JCGT 2018). ``eval`` returns ``f * cos(theta_i)`` per colour and the solid-angle pdf of
``sample``; ``sample`` returns the direction and the weight ``f * cos / pdf``.
"""

from __future__ import annotations

import math

from numba import njit

from .vecmath import luminance, normalize

DIFFUSE, CONDUCTOR, PLASTIC, DIELECTRIC, MIRROR = 0, 1, 2, 3, 4
MIN_ALPHA = 1e-3
INV_PI = 1.0 / math.pi


@njit(cache=True, error_model="numpy")
def is_delta(kind):
    """True for materials whose scattering is a Dirac delta (no light sampling)."""
    return kind == DIELECTRIC or kind == MIRROR


@njit(cache=True, error_model="numpy")
def _ggx_d(hz, a2):
    c2 = hz * hz
    d = c2 * (a2 - 1.0) + 1.0
    return a2 / (math.pi * d * d)


@njit(cache=True, error_model="numpy")
def _ggx_lambda(wz, a2):
    c2 = wz * wz
    if c2 <= 0.0:
        return 1e30
    t2 = max(1.0 - c2, 0.0) / c2
    return 0.5 * (-1.0 + math.sqrt(1.0 + a2 * t2))


@njit(cache=True, error_model="numpy")
def _schlick(f0, c):
    m = 1.0 - c
    m2 = m * m
    return f0 + (1.0 - f0) * (m2 * m2 * m)


@njit(cache=True, error_model="numpy")
def fresnel_dielectric(cos_i, eta):
    """Unpolarised Fresnel reflectance; ``eta = eta_t / eta_i``, ``cos_i >= 0``."""
    sin_t2 = (1.0 - cos_i * cos_i) / (eta * eta)
    if sin_t2 >= 1.0:
        return 1.0
    cos_t = math.sqrt(1.0 - sin_t2)
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return 0.5 * (rs * rs + rp * rp)


@njit(cache=True, error_model="numpy")
def _plastic_spec_prob(wo_z, f0, albedo_lum):
    fo = _schlick(f0, wo_z)
    p = fo / (fo + (1.0 - fo) * albedo_lum + 1e-12)
    return min(max(p, 0.1), 0.9)


@njit(cache=True, error_model="numpy", inline="always")
def _ggx_terms(wo, wi, a2):
    """(D, G2, G1(wo), cos(wo, h)) of the half vector of wo and wi (both above the surface)."""
    h = normalize((wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]))
    lo = _ggx_lambda(wo[2], a2)
    li = _ggx_lambda(wi[2], a2)
    d = _ggx_d(h[2], a2)
    c = max(wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2], 0.0)
    return d, 1.0 / (1.0 + lo + li), 1.0 / (1.0 + lo), c


@njit(cache=True, error_model="numpy", inline="always")
def bsdf_eval(kind, alb, alpha, spec, wo, wi):
    """``f * cos(theta_i)`` (r, g, b) and the pdf of :func:`bsdf_sample` for wi.

    Parameters
    ----------
    kind : int
    alb, spec : 3-tuples
        Albedo (textured) and normal-incidence specular reflectance.
    alpha : float
        GGX roughness (alpha).
    wo, wi : 3-tuples
        Unit directions in the local frame (towards the viewer and towards the light).
    """
    if wo[2] <= 0.0 or wi[2] <= 0.0 or is_delta(kind):
        return 0.0, 0.0, 0.0, 0.0
    if kind == DIFFUSE:
        c = wi[2] * INV_PI
        return alb[0] * c, alb[1] * c, alb[2] * c, c
    a = max(alpha, MIN_ALPHA)
    a2 = a * a
    d, g2, g1, c = _ggx_terms(wo, wi, a2)
    s = d * g2 / (4.0 * wo[2])
    pdf_s = g1 * d / (4.0 * wo[2])
    if kind == CONDUCTOR:
        return (_schlick(spec[0], c) * s, _schlick(spec[1], c) * s, _schlick(spec[2], c) * s, pdf_s)
    f0 = (spec[0] + spec[1] + spec[2]) / 3.0
    kd = (1.0 - _schlick(f0, wo[2])) * wi[2] * INV_PI
    ps = _plastic_spec_prob(wo[2], f0, luminance(alb[0], alb[1], alb[2]))
    pdf = ps * pdf_s + (1.0 - ps) * wi[2] * INV_PI
    return (
        _schlick(spec[0], c) * s + alb[0] * kd,
        _schlick(spec[1], c) * s + alb[1] * kd,
        _schlick(spec[2], c) * s + alb[2] * kd,
        pdf,
    )


@njit(cache=True, error_model="numpy", inline="always")
def _sample_vndf(wo, a, u1, u2):
    vh = normalize((a * wo[0], a * wo[1], wo[2]))
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
    nh = (p1 * t1[0] + p2 * t2[0] + p3 * vh[0],
          p1 * t1[1] + p2 * t2[1] + p3 * vh[1],
          p1 * t1[2] + p2 * t2[2] + p3 * vh[2])
    return normalize((a * nh[0], a * nh[1], max(nh[2], 0.0)))


@njit(cache=True, error_model="numpy", inline="always")
def bsdf_sample(kind, alb, alpha, spec, ior, wo, u1, u2, u3):
    """Sample an incident direction.

    Returns
    -------
    wi : 3-tuple
        Local direction (zero vector when the sample is absorbed).
    wr, wg, wb : float
        Weight ``f * cos / pdf`` (for delta lobes: the lobe's reflectance or transmittance).
    pdf : float
        Solid-angle pdf (1 for delta lobes, where it is not used).
    delta : bool
    """
    zero = (0.0, 0.0, 0.0)
    if kind == DIELECTRIC:
        cos_o = wo[2]
        if cos_o >= 0.0:
            eta, side = ior, 1.0
        else:
            eta, side = 1.0 / ior, -1.0
        c = abs(cos_o)
        fr = fresnel_dielectric(c, eta)
        if u1 < fr:
            return (-wo[0], -wo[1], wo[2]), 1.0, 1.0, 1.0, 1.0, True
        cos_t = math.sqrt(max(1.0 - (1.0 - c * c) / (eta * eta), 0.0))
        k = c / eta - cos_t
        wi = normalize((-wo[0] / eta, -wo[1] / eta, -wo[2] / eta + k * side))
        tr = 1.0 / (eta * eta)
        return wi, tr, tr, tr, 1.0, True
    if wo[2] <= 0.0:
        return zero, 0.0, 0.0, 0.0, 0.0, False
    if kind == MIRROR:
        return (-wo[0], -wo[1], wo[2]), 1.0, 1.0, 1.0, 1.0, True
    if kind == DIFFUSE:
        r = math.sqrt(u1)
        phi = 2.0 * math.pi * u2
        wi = (r * math.cos(phi), r * math.sin(phi), math.sqrt(max(1.0 - u1, 0.0)))
        if wi[2] <= 0.0:
            return zero, 0.0, 0.0, 0.0, 0.0, False
        return wi, alb[0], alb[1], alb[2], wi[2] * INV_PI, False
    a = max(alpha, MIN_ALPHA)
    use_spec = True
    if kind == PLASTIC:
        f0 = (spec[0] + spec[1] + spec[2]) / 3.0
        use_spec = u3 < _plastic_spec_prob(wo[2], f0, luminance(alb[0], alb[1], alb[2]))
    if use_spec:
        h = _sample_vndf(wo, a, u1, u2)
        c = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
        wi = (2.0 * c * h[0] - wo[0], 2.0 * c * h[1] - wo[1], 2.0 * c * h[2] - wo[2])
    else:
        r = math.sqrt(u1)
        phi = 2.0 * math.pi * u2
        wi = (r * math.cos(phi), r * math.sin(phi), math.sqrt(max(1.0 - u1, 0.0)))
    if wi[2] <= 0.0:
        return zero, 0.0, 0.0, 0.0, 0.0, False
    fr, fg, fb, pdf = bsdf_eval(kind, alb, alpha, spec, wo, wi)
    if pdf <= 0.0:
        return zero, 0.0, 0.0, 0.0, 0.0, False
    return wi, fr / pdf, fg / pdf, fb / pdf, pdf, False
