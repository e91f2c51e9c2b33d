"""Surface scattering in the local shading frame (z = normal): the harness kinds and Mitsuba's BSDFs.

Harness kinds (``harness.scene.MATERIAL_KINDS`` order): 0 diffuse (Lambert), 1 conductor (GGX microfacet
with Schlick Fresnel of normal reflectance ``specular``), 2 plastic (Lambertian base under a GGX
coat: ``f = F D G / (4 cos_o cos_i) + (1 - F(cos_o)) albedo / pi``, a simple energy-bounded
layering without internal reflections), 3 dielectric (smooth glass, exact Fresnel; radiance is
scaled by ``(eta_i / eta_t)^2`` on refraction), 4 mirror (perfect specular reflection, reflectance 1).

The GGX distribution uses Smith's height-correlated masking-shadowing and is sampled with the
distribution of visible normals (Heitz, "Sampling the GGX distribution of visible normals",
JCGT 2018). ``eval`` returns ``f * cos(theta_i)`` per colour and the solid-angle pdf of
``sample``; ``sample`` returns the direction and the weight ``f * cos / pdf``.

Mitsuba's BSDFs (``docs/pathtracer.md`` has their equations), evaluated as Mitsuba 3 defines them:
5 roughdiffuse (Oren-Nayar, qualitative form), 6 plastic and 7 roughplastic (Fresnel-weighted
specular; diffuse scaled by the Fresnel transmittance in and out, ``1 / eta^2`` and the internal
scattering factor, ``nonlinear`` honoured), 8 conductor and 9 roughconductor (complex-index
Fresnel times ``specular_reflectance``; GGX or Beckmann, anisotropic), 10 roughdielectric (Walter
et al. 2007), 11 thindielectric. Mitsuba's ``diffuse`` and ``dielectric`` are kinds 0 and 3 (the
dielectric scaled by ``specular_reflectance`` / ``specular_transmittance``, 1 for harness
materials). Parameters live in a row of ``node_f`` (columns ``F_*``); colours A (diffuse or
specular reflectance) and B (specular reflectance or transmittance) arrive textured.
"""

from __future__ import annotations

import math

from numba import njit

from .fresnel import conductor_rgb, dielectric, dielectric_signed
from .microfacet import mf_d, mf_g1, mf_pdf, mf_sample
from .vecmath import luminance, normalize

DIFFUSE, CONDUCTOR, PLASTIC, DIELECTRIC, MIRROR = 0, 1, 2, 3, 4
ROUGHDIFFUSE, MI_PLASTIC, MI_ROUGHPLASTIC, MI_CONDUCTOR, MI_ROUGHCONDUCTOR = 5, 6, 7, 8, 9
MI_ROUGHDIELECTRIC, MI_THINDIELECTRIC = 10, 11
TWOSIDED, MASK, BLEND, BUMP = 20, 21, 22, 23
# columns of node_f: colours A and B, complex index (eta, k), roughness (alpha_u, alpha_v), distribution
# (0 GGX, 1 Beckmann), nonlinear, internal reflectance, specular sampling weight, scalar slot S (3)
F_A, F_B, F_ETA, F_K, F_AU, F_AV, F_DIST, F_NONLINEAR, F_RI, F_SSW, F_S = 0, 3, 6, 9, 12, 13, 14, 15, 16, 17, 18
NF = 21
# columns of node_i: textures of slots A, B, S; children; offset of the rough-transmittance table
I_TEX_A, I_TEX_B, I_TEX_S, I_CHILD0, I_CHILD1, I_TABLE = 0, 1, 2, 3, 4, 5
NI = 6
TABLE_RES = 64
MIN_ALPHA = 1e-3
INV_PI = 1.0 / math.pi


@njit(cache=True, error_model="numpy")
def is_delta(kind):
    """True for BSDFs whose scattering is a Dirac delta (no light sampling)."""
    return kind == DIELECTRIC or kind == MIRROR or kind == MI_CONDUCTOR or kind == MI_THINDIELECTRIC


@njit(cache=True, error_model="numpy")
def is_transmissive(kind):
    """True for BSDFs that scatter to both sides of the surface (their frame is not turned to the viewer)."""
    return kind == DIELECTRIC or kind == MI_ROUGHDIELECTRIC or kind == MI_THINDIELECTRIC


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
def _legacy_eval(kind, alb, alpha, spec, wo, wi):
    """``f * cos(theta_i)`` (r, g, b) and the pdf of sampling wi, for the harness kinds.

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


@njit(cache=True, error_model="numpy")
def _legacy_sample(kind, alb, alpha, spec, ior, wo, u1, u2, u3):
    """Sample an incident direction (harness kinds).

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
        fr = dielectric(c, eta)
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
        h = mf_sample(wo, a, a, 0, u1, u2)  # GGX (isotropic): its visible normals
        c = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
        wi = (2.0 * c * h[0] - wo[0], 2.0 * c * h[1] - wo[1], 2.0 * c * h[2] - wo[2])
    else:
        r = math.sqrt(u1)
        phi = 2.0 * math.pi * u2
        wi = (r * math.cos(phi), r * math.sin(phi), math.sqrt(max(1.0 - u1, 0.0)))
    if wi[2] <= 0.0:
        return zero, 0.0, 0.0, 0.0, 0.0, False
    fr, fg, fb, pdf = _legacy_eval(kind, alb, alpha, spec, wo, wi)
    if pdf <= 0.0:
        return zero, 0.0, 0.0, 0.0, 0.0, False
    return wi, fr / pdf, fg / pdf, fb / pdf, pdf, False


@njit(cache=True, error_model="numpy", inline="always")
def _lerp_table(tables, off, c):
    """Mitsuba's linear lookup of a 64-entry table over cos(theta) in [0, 1]."""
    x = min(max(c, 0.0), 1.0) * (TABLE_RES - 1)
    i = min(int(x), TABLE_RES - 2)
    w = x - i
    return (1.0 - w) * tables[off + i] + w * tables[off + i + 1]


@njit(cache=True, error_model="numpy", inline="always")
def _plastic_terms(kind, node, nf, ni, tables, cos_o):
    """(probability of the specular lobe, transmittance of the coat towards the viewer)."""
    if kind == MI_PLASTIC:
        t_o = 1.0 - dielectric(cos_o, nf[node, F_ETA])
    else:
        t_o = _lerp_table(tables, ni[node, I_TABLE], cos_o)
    ssw = nf[node, F_SSW]
    ps = (1.0 - t_o) * ssw
    pd = t_o * (1.0 - ssw)
    return (ps / (ps + pd) if ps + pd > 0.0 else 0.0), t_o


@njit(cache=True, error_model="numpy", inline="always")
def _plastic_diffuse(kind, node, nf, ni, tables, a, t_o, wi):
    """The diffuse lobe of (rough)plastic, ``f * cos(theta_i)`` per colour."""
    if kind == MI_PLASTIC:
        t_i = 1.0 - dielectric(wi[2], nf[node, F_ETA])
    else:
        t_i = _lerp_table(tables, ni[node, I_TABLE], wi[2])
    eta = nf[node, F_ETA]
    k = t_i * t_o * wi[2] * INV_PI / (eta * eta)
    ri = nf[node, F_RI]
    if nf[node, F_NONLINEAR] > 0.0:
        return (a[0] / (1.0 - a[0] * ri) * k, a[1] / (1.0 - a[1] * ri) * k, a[2] / (1.0 - a[2] * ri) * k)
    return (a[0] / (1.0 - ri) * k, a[1] / (1.0 - ri) * k, a[2] / (1.0 - ri) * k)


@njit(cache=True, error_model="numpy", inline="always")
def _alphas(node, nf):
    return max(nf[node, F_AU], 1e-4), max(nf[node, F_AV], 1e-4), int(nf[node, F_DIST])


@njit(cache=True, error_model="numpy")
def _rough_dielectric(node, nf, a, b, wo, wi):
    """``f * |cos(theta_i)|`` and pdf of Mitsuba's roughdielectric for any pair of sides."""
    cos_o = wo[2]
    cos_i = wi[2]
    if cos_o == 0.0 or cos_i == 0.0:
        return 0.0, 0.0, 0.0, 0.0
    au, av, dist = _alphas(node, nf)
    eta = nf[node, F_ETA]
    reflect = cos_o * cos_i > 0.0
    eta_path = eta if cos_o > 0.0 else 1.0 / eta
    if reflect:
        m = normalize((wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]))
    else:
        m = normalize((wo[0] + wi[0] * eta_path, wo[1] + wi[1] * eta_path, wo[2] + wi[2] * eta_path))
    if m[2] < 0.0:
        m = (-m[0], -m[1], -m[2])
    do = wo[0] * m[0] + wo[1] * m[1] + wo[2] * m[2]
    di = wi[0] * m[0] + wi[1] * m[1] + wi[2] * m[2]
    if do * cos_o <= 0.0 or di * cos_i <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    d = mf_d(m, au, av, dist)
    g = mf_g1(wo, m, au, av, dist) * mf_g1(wi, m, au, av, dist)
    f = dielectric_signed(do, eta)[0]
    up = (wo[0], wo[1], wo[2]) if cos_o > 0.0 else (-wo[0], -wo[1], -wo[2])
    pm = mf_pdf(up, m, au, av, dist)
    if reflect:
        v = f * d * g / (4.0 * abs(cos_o))
        pdf = f * pm / (4.0 * abs(do))
        return a[0] * v, a[1] * v, a[2] * v, pdf
    den = do + eta_path * di
    den2 = den * den
    if den2 <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    v = abs((1.0 - f) * d * g * do * di / (cos_o * den2))
    pdf = (1.0 - f) * pm * abs(eta_path * eta_path * di) / den2
    return b[0] * v, b[1] * v, b[2] * v, pdf


@njit(cache=True, error_model="numpy", inline="always")
def bsdf_eval(kind, node, nf, ni, tables, a, b, wo, wi):
    """``f * |cos(theta_i)|`` (r, g, b) and the pdf of :func:`bsdf_sample` for ``wi``.

    The Lambertian case (most surfaces of most scenes) is computed where this is inlined; the
    others in the called :func:`eval_any` (inlining every BSDF into the path kernel multiplies
    its compile time).

    Parameters
    ----------
    kind, node : int
        The leaf's kind and row in ``nf``/``ni``.
    nf, ni, tables : node tables (see :mod:`.materials`).
    a, b : 3-tuples
        Colours A and B of the node, textured.
    wo, wi : 3-tuples
        Unit directions in the local frame (towards the viewer and towards the light).
    """
    if kind == DIFFUSE:
        if wo[2] <= 0.0 or wi[2] <= 0.0:
            return 0.0, 0.0, 0.0, 0.0
        c = wi[2] * INV_PI
        return a[0] * c, a[1] * c, a[2] * c, c
    return eval_any(kind, node, nf, ni, tables, a, b, wo, wi)


@njit(cache=True, error_model="numpy")
def eval_any(kind, node, nf, ni, tables, a, b, wo, wi):
    """:func:`bsdf_eval` for any kind (same arguments and result)."""
    if is_delta(kind):
        return 0.0, 0.0, 0.0, 0.0
    if kind == MI_ROUGHDIELECTRIC:
        return _rough_dielectric(node, nf, a, b, wo, wi)
    if wo[2] <= 0.0 or wi[2] <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    if kind <= MIRROR:
        return _legacy_eval(kind, a, nf[node, F_AU], b, wo, wi)
    if kind == ROUGHDIFFUSE:
        sigma2 = 0.5 * nf[node, F_AU] * nf[node, F_AU]
        ca = 1.0 - 0.5 * sigma2 / (sigma2 + 0.33)
        cb = 0.45 * sigma2 / (sigma2 + 0.09)
        sin_o = math.sqrt(max(1.0 - wo[2] * wo[2], 0.0))
        sin_i = math.sqrt(max(1.0 - wi[2] * wi[2], 0.0))
        cos_phi = 0.0
        if sin_o > 1e-9 and sin_i > 1e-9:
            cos_phi = max((wo[0] * wi[0] + wo[1] * wi[1]) / (sin_o * sin_i), 0.0)
        if wi[2] < wo[2]:
            sin_a, tan_b = sin_i, sin_o / wo[2]
        else:
            sin_a, tan_b = sin_o, sin_i / wi[2]
        k = (ca + cb * cos_phi * sin_a * tan_b) * wi[2] * INV_PI
        return a[0] * k, a[1] * k, a[2] * k, wi[2] * INV_PI
    if kind == MI_PLASTIC or kind == MI_ROUGHPLASTIC:
        ps, t_o = _plastic_terms(kind, node, nf, ni, tables, wo[2])
        dr, dg, db = _plastic_diffuse(kind, node, nf, ni, tables, a, t_o, wi)
        pdf = (1.0 - ps) * wi[2] * INV_PI
        if kind == MI_PLASTIC:
            return dr, dg, db, pdf
        au, av, dist = _alphas(node, nf)
        h = normalize((wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]))
        c = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
        if c <= 0.0:
            return dr, dg, db, pdf
        v = dielectric(c, nf[node, F_ETA]) * mf_d(h, au, av, dist) * mf_g1(wo, h, au, av, dist) * mf_g1(
            wi, h, au, av, dist) / (4.0 * wo[2])
        pdf += ps * mf_pdf(wo, h, au, av, dist) / (4.0 * c)
        return dr + b[0] * v, dg + b[1] * v, db + b[2] * v, pdf
    # MI_ROUGHCONDUCTOR
    au, av, dist = _alphas(node, nf)
    h = normalize((wo[0] + wi[0], wo[1] + wi[1], wo[2] + wi[2]))
    c = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
    if c <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    v = mf_d(h, au, av, dist) * mf_g1(wo, h, au, av, dist) * mf_g1(wi, h, au, av, dist) / (4.0 * wo[2])
    fr, fg, fb = conductor_rgb(c, nf, node, F_ETA, F_K)
    return b[0] * fr * v, b[1] * fg * v, b[2] * fb * v, mf_pdf(wo, h, au, av, dist) / (4.0 * c)


@njit(cache=True, error_model="numpy", inline="always")
def _cosine(u1, u2):
    r = math.sqrt(u1)
    phi = 2.0 * math.pi * u2
    return (r * math.cos(phi), r * math.sin(phi), math.sqrt(max(1.0 - u1, 0.0)))


@njit(cache=True, error_model="numpy", inline="always")
def bsdf_sample(kind, node, nf, ni, tables, a, b, wo, u1, u2, u3):
    """Sample a direction towards the light (the Lambertian case inlined, as in :func:`bsdf_eval`).

    Returns
    -------
    wi : 3-tuple
        Local direction (zero vector when the sample is absorbed).
    wr, wg, wb : float
        Weight ``f * |cos| / pdf`` (delta lobes: the lobe's reflectance or transmittance over its
        selection probability).
    pdf : float
        Solid-angle pdf (for delta lobes the selection probability, unused).
    delta : bool
    """
    if kind == DIFFUSE:
        if wo[2] <= 0.0:
            return (0.0, 0.0, 0.0), 0.0, 0.0, 0.0, 0.0, False
        wi = _cosine(u1, u2)
        if wi[2] <= 0.0:
            return (0.0, 0.0, 0.0), 0.0, 0.0, 0.0, 0.0, False
        return wi, a[0], a[1], a[2], wi[2] * INV_PI, False
    return sample_any(kind, node, nf, ni, tables, a, b, wo, u1, u2, u3)


@njit(cache=True, error_model="numpy")
def sample_any(kind, node, nf, ni, tables, a, b, wo, u1, u2, u3):
    """:func:`bsdf_sample` for any kind (same arguments and result)."""
    zero = (0.0, 0.0, 0.0)
    if kind <= MIRROR:
        wi, wr, wg, wb, pdf, dlt = _legacy_sample(kind, a, nf[node, F_AU], b, nf[node, F_ETA], wo, u1, u2, u3)
        if kind == DIELECTRIC:
            if wi[2] * wo[2] > 0.0:
                return wi, wr * a[0], wg * a[1], wb * a[2], pdf, dlt
            return wi, wr * b[0], wg * b[1], wb * b[2], pdf, dlt
        return wi, wr, wg, wb, pdf, dlt
    if kind == MI_THINDIELECTRIC:
        r = dielectric(abs(wo[2]), nf[node, F_ETA])
        if r < 1.0:
            r += (1.0 - r) * (1.0 - r) * r / (1.0 - r * r)
        if u3 < r:
            return (-wo[0], -wo[1], wo[2]), a[0], a[1], a[2], r, True
        return (-wo[0], -wo[1], -wo[2]), b[0], b[1], b[2], 1.0 - r, True
    if kind == MI_ROUGHDIELECTRIC:
        au, av, dist = _alphas(node, nf)
        up = (wo[0], wo[1], wo[2]) if wo[2] > 0.0 else (-wo[0], -wo[1], -wo[2])
        m = mf_sample(up, au, av, dist, u1, u2)
        c = wo[0] * m[0] + wo[1] * m[1] + wo[2] * m[2]
        f, cos_t, eta_it = dielectric_signed(c, nf[node, F_ETA])
        if u3 < f:
            wi = (2.0 * c * m[0] - wo[0], 2.0 * c * m[1] - wo[1], 2.0 * c * m[2] - wo[2])
        else:
            e = 1.0 / eta_it
            wi = normalize((m[0] * (c * e + cos_t) - wo[0] * e, m[1] * (c * e + cos_t) - wo[1] * e,
                            m[2] * (c * e + cos_t) - wo[2] * e))
        fr, fg, fb, pdf = _rough_dielectric(node, nf, a, b, wo, wi)
        if pdf <= 0.0:
            return zero, 0.0, 0.0, 0.0, 0.0, False
        return wi, fr / pdf, fg / pdf, fb / pdf, pdf, False
    if wo[2] <= 0.0:
        return zero, 0.0, 0.0, 0.0, 0.0, False
    if kind == MI_CONDUCTOR:
        fr, fg, fb = conductor_rgb(wo[2], nf, node, F_ETA, F_K)
        return (-wo[0], -wo[1], wo[2]), b[0] * fr, b[1] * fg, b[2] * fb, 1.0, True
    if kind == MI_PLASTIC or kind == MI_ROUGHPLASTIC:
        ps, t_o = _plastic_terms(kind, node, nf, ni, tables, wo[2])
        if u3 < ps:
            if kind == MI_PLASTIC:
                f = dielectric(wo[2], nf[node, F_ETA]) / ps
                return (-wo[0], -wo[1], wo[2]), b[0] * f, b[1] * f, b[2] * f, ps, True
            au, av, dist = _alphas(node, nf)
            m = mf_sample(wo, au, av, dist, u1, u2)
            c = wo[0] * m[0] + wo[1] * m[1] + wo[2] * m[2]
            wi = (2.0 * c * m[0] - wo[0], 2.0 * c * m[1] - wo[1], 2.0 * c * m[2] - wo[2])
        else:
            wi = _cosine(u1, u2)
    elif kind == MI_ROUGHCONDUCTOR:
        au, av, dist = _alphas(node, nf)
        m = mf_sample(wo, au, av, dist, u1, u2)
        c = wo[0] * m[0] + wo[1] * m[1] + wo[2] * m[2]
        wi = (2.0 * c * m[0] - wo[0], 2.0 * c * m[1] - wo[1], 2.0 * c * m[2] - wo[2])
    else:
        wi = _cosine(u1, u2)
    if wi[2] <= 0.0:
        return zero, 0.0, 0.0, 0.0, 0.0, False
    fr, fg, fb, pdf = bsdf_eval(kind, node, nf, ni, tables, a, b, wo, wi)
    if pdf <= 0.0:
        return zero, 0.0, 0.0, 0.0, 0.0, False
    return wi, fr / pdf, fg / pdf, fb / pdf, pdf, False
