"""Light sources: emissive triangles, the sun (a cone of directions), the environment and delta lights.

Next-event estimation first picks a light group with probabilities proportional to estimated
power (emissive triangles: ``2 pi A L`` where both faces emit, ``pi A L`` for one-sided emitters;
sun and environment: ``pi r^2`` times the integral of their radiance over directions, with ``r``
the radius of the scene's bounding sphere), then a triangle in proportion to its power (area x
luminance of emission) and a uniform point on it, a uniform direction in the sun's cone, or a
direction from the environment (piecewise-constant importance sampling of luminance x
sin(theta) for maps, uniform on the sphere for the constant and sky kinds).

Delta lights (Mitsuba's ``spot``; ``Scene.params["delta_lights"]``) are a point each, of radiant
intensity ``I f(theta)`` towards a direction at angle ``theta`` from the spot's axis (``f``:
Mitsuba's falloff, 1 inside ``beam_width``, ``(cutoff - theta) / (cutoff - beam_width)`` out to
``cutoff_angle``, 0 beyond); a group of their own chosen in proportion to ``I 2 pi (1 - cos
cutoff)``, then one in proportion to that too. Only next-event estimation reaches them: their
sample's pdf is the discrete probability of choosing the light, its MIS weight 1 (the triangle
returned is :data:`DELTA_LIGHT`), and BSDF sampling never hits them (``strategy="bsdf"`` does not
see them, as in any renderer).

Sun and environment are treated as one infinite light: a direction that leaves the scene gets
the sum of their radiances, and its light pdf is the mixture ``p_sun pdf_sun + p_env pdf_env``.

Equirectangular map convention: a direction ``d`` (after undoing ``rotation`` about +y) has
``u = 0.5 + atan2(d_x, -d_z) / (2 pi)`` (columns, left to right) and ``v = acos(d_y) / pi`` (rows,
top = +y).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .vecmath import onb, to_world

# indices into the float64 light-parameter vector ``lp``
SUN_DIR, SUN_COS, SUN_RAD, P_SUN = 0, 3, 4, 7
ENV_KIND, ENV_RAD, ENV_HORIZON, P_ENV, P_TRI, ENV_ROT = 8, 9, 12, 15, 16, 17
P_DELTA, N_DELTA = 18, 19
N_PARAMS = 20
# after the N_PARAMS fixed entries, DELTA_STRIDE per delta light: position (3), world-to-local matrix
# (9, row-major; local +z is the spot's axis), intensity (3), cos(cutoff), cos(beam width), cutoff
# (radians), 1 / (cutoff - beam width), cumulative choice probability up to this light
D_POS, D_TO_LOCAL, D_INTENSITY = 0, 3, 12
D_COS_CUTOFF, D_COS_BEAM, D_CUTOFF, D_INV_TRANSITION, D_CDF = 15, 16, 17, 18, 19
DELTA_STRIDE = 20
DELTA_LIGHT = -2  # the "triangle" of a delta light's sample
ENV_NONE, ENV_CONSTANT, ENV_SKY, ENV_MAP = -1, 0, 1, 2
MIN_SUN_RADIUS_DEG = 0.01


@njit(cache=True, error_model="numpy")
def _search(cdf, lo, hi, u):
    """Index k in [lo, hi - 1) with cdf[k] <= u < cdf[k + 1] (cdf[lo] = 0, cdf[hi - 1] = 1)."""
    a = lo
    b = hi - 1
    while b - a > 1:
        m = (a + b) // 2
        if cdf[m] <= u:
            a = m
        else:
            b = m
    return a


@njit(cache=True, error_model="numpy")
def _rot_y(x, z, angle):
    c = math.cos(angle)
    s = math.sin(angle)
    return c * x + s * z, -s * x + c * z


@njit(cache=True, error_model="numpy", inline="always")
def _map_pixel(d, lp, h, w):
    x, z = d[0], d[2]
    if lp[ENV_ROT] != 0.0:
        x, z = _rot_y(x, z, -lp[ENV_ROT])
    u = 0.5 + math.atan2(x, -z) / (2.0 * math.pi)
    v = math.acos(min(max(d[1], -1.0), 1.0)) / math.pi
    col = min(max(int(u * w), 0), w - 1)
    row = min(max(int(v * h), 0), h - 1)
    return row, col


@njit(cache=True, error_model="numpy", inline="always")
def _radiance_at(d, lp, env_img, kind, row, col):
    """Sun plus environment radiance towards ``d``; ``row``, ``col``: the map's texel of ``d`` (maps only)."""
    r = g = b = 0.0
    if kind == ENV_CONSTANT:
        r, g, b = lp[ENV_RAD], lp[ENV_RAD + 1], lp[ENV_RAD + 2]
    elif kind == ENV_SKY:
        t = max(d[1], 0.0)
        r = lp[ENV_HORIZON] + (lp[ENV_RAD] - lp[ENV_HORIZON]) * t
        g = lp[ENV_HORIZON + 1] + (lp[ENV_RAD + 1] - lp[ENV_HORIZON + 1]) * t
        b = lp[ENV_HORIZON + 2] + (lp[ENV_RAD + 2] - lp[ENV_HORIZON + 2]) * t
    elif kind == ENV_MAP:
        r = env_img[row, col, 0] * lp[ENV_RAD]
        g = env_img[row, col, 1] * lp[ENV_RAD + 1]
        b = env_img[row, col, 2] * lp[ENV_RAD + 2]
    if lp[SUN_COS] < 1.0:
        c = d[0] * lp[SUN_DIR] + d[1] * lp[SUN_DIR + 1] + d[2] * lp[SUN_DIR + 2]
        if c >= lp[SUN_COS]:
            r += lp[SUN_RAD]
            g += lp[SUN_RAD + 1]
            b += lp[SUN_RAD + 2]
    return r, g, b


@njit(cache=True, error_model="numpy", inline="always")
def infinite_radiance(d, lp, env_img):
    """Radiance (r, g, b) arriving from the unit direction ``d`` from sun and environment."""
    kind = int(lp[ENV_KIND])
    row = col = 0
    if kind == ENV_MAP:
        row, col = _map_pixel(d, lp, env_img.shape[0], env_img.shape[1])
    return _radiance_at(d, lp, env_img, kind, row, col)


@njit(cache=True, error_model="numpy", inline="always")
def infinite_radiance_pdf(d, lp, env_img, cdf_rows, cdf_cols):
    """:func:`infinite_radiance` of ``d`` and the solid-angle density with which :func:`sample_light`
    produces the escaping direction ``d`` (one map lookup serves both)."""
    kind = int(lp[ENV_KIND])
    h, w = env_img.shape[0], env_img.shape[1]
    row = col = 0
    if kind == ENV_MAP:
        row, col = _map_pixel(d, lp, h, w)
    r, g, b = _radiance_at(d, lp, env_img, kind, row, col)
    pdf = 0.0
    if lp[P_SUN] > 0.0:
        c = d[0] * lp[SUN_DIR] + d[1] * lp[SUN_DIR + 1] + d[2] * lp[SUN_DIR + 2]
        if c >= lp[SUN_COS]:
            pdf += lp[P_SUN] / (2.0 * math.pi * (1.0 - lp[SUN_COS]))
    if lp[P_ENV] > 0.0:
        if kind == ENV_MAP:
            sin_t = math.sqrt(max(1.0 - d[1] * d[1], 0.0))
            if sin_t > 0.0:
                mass = (cdf_rows[row + 1] - cdf_rows[row]) * (cdf_cols[row, col + 1] - cdf_cols[row, col])
                pdf += lp[P_ENV] * mass * (w * h) / (2.0 * math.pi * math.pi * sin_t)
        else:
            pdf += lp[P_ENV] / (4.0 * math.pi)
    return r, g, b, pdf


@njit(cache=True, error_model="numpy", inline="always")
def sample_light(u0, u1, u2, p, lp, tri_v, tri_mat, mat_emit, mat_flags, tri_front, emit_tri, emit_cdf,
                 tri_light_pdf, env_img, cdf_rows, cdf_cols):
    """Sample a light as seen from point ``p``.

    A triangle of a one-sided emitter (``mat_flags & 1``, Mitsuba's ``area``) emits only on the
    side of its normal oriented by ``tri_front`` (the winding normal's sign against the shading
    normals); both sides otherwise.

    Returns
    -------
    d : 3-tuple
        Unit direction from ``p`` towards the light sample.
    dist : float
        Distance to the sample (inf for sun and environment).
    le : 3-tuple
        Radiance arriving along ``-d`` if unoccluded.
    pdf : float
        Solid-angle pdf including the choice of light (0: no sample).
    tri : int
        The emissive triangle sampled, or -1.
    """
    zero = (0.0, 0.0, 0.0)
    if u0 < lp[P_TRI]:
        u = u0 / lp[P_TRI]
        k = _search(emit_cdf, 0, emit_cdf.shape[0], u)
        t = emit_tri[k]
        su = math.sqrt(u1)
        b0 = 1.0 - su
        b1 = u2 * su
        b2 = 1.0 - b0 - b1
        qx = b0 * tri_v[t, 0] + b1 * tri_v[t, 3] + b2 * tri_v[t, 6]
        qy = b0 * tri_v[t, 1] + b1 * tri_v[t, 4] + b2 * tri_v[t, 7]
        qz = b0 * tri_v[t, 2] + b1 * tri_v[t, 5] + b2 * tri_v[t, 8]
        dx, dy, dz = qx - p[0], qy - p[1], qz - p[2]
        d2 = dx * dx + dy * dy + dz * dz
        if d2 <= 0.0:
            return zero, 0.0, zero, 0.0, -1
        dist = math.sqrt(d2)
        d = (dx / dist, dy / dist, dz / dist)
        e1 = (tri_v[t, 3] - tri_v[t, 0], tri_v[t, 4] - tri_v[t, 1], tri_v[t, 5] - tri_v[t, 2])
        e2 = (tri_v[t, 6] - tri_v[t, 0], tri_v[t, 7] - tri_v[t, 1], tri_v[t, 8] - tri_v[t, 2])
        nx = e1[1] * e2[2] - e1[2] * e2[1]
        ny = e1[2] * e2[0] - e1[0] * e2[2]
        nz = e1[0] * e2[1] - e1[1] * e2[0]
        nl = math.sqrt(nx * nx + ny * ny + nz * nz)
        if nl <= 0.0:
            return zero, 0.0, zero, 0.0, -1
        cos_signed = -(nx * d[0] + ny * d[1] + nz * d[2]) / nl
        cos_l = abs(cos_signed)
        if cos_l <= 1e-8:
            return zero, 0.0, zero, 0.0, -1
        m = tri_mat[t]
        if (mat_flags[m] & 1) != 0 and tri_front[t] * cos_signed <= 0.0:
            return zero, 0.0, zero, 0.0, -1
        le = (np.float64(mat_emit[m, 0]), np.float64(mat_emit[m, 1]), np.float64(mat_emit[m, 2]))
        return d, dist, le, tri_light_pdf[t] * d2 / cos_l, t
    if u0 >= lp[P_TRI] + lp[P_SUN] and u0 < lp[P_TRI] + lp[P_SUN] + lp[P_DELTA]:
        return sample_delta((u0 - lp[P_TRI] - lp[P_SUN]) / lp[P_DELTA], p, lp)
    if u0 < lp[P_TRI] + lp[P_SUN]:
        ct = 1.0 - u1 * (1.0 - lp[SUN_COS])
        st = math.sqrt(max(1.0 - ct * ct, 0.0))
        phi = 2.0 * math.pi * u2
        n = (lp[SUN_DIR], lp[SUN_DIR + 1], lp[SUN_DIR + 2])
        t1, t2 = onb(n)
        d = to_world((st * math.cos(phi), st * math.sin(phi), ct), t1, t2, n)
    else:
        kind = int(lp[ENV_KIND])
        if kind == ENV_MAP:
            h, w = env_img.shape[0], env_img.shape[1]
            row = _search(cdf_rows, 0, h + 1, u1)
            pr = cdf_rows[row + 1] - cdf_rows[row]
            fv = (u1 - cdf_rows[row]) / pr if pr > 0.0 else 0.5
            col = _search(cdf_cols[row], 0, w + 1, u2)
            pc = cdf_cols[row, col + 1] - cdf_cols[row, col]
            fu = (u2 - cdf_cols[row, col]) / pc if pc > 0.0 else 0.5
            theta = (row + min(max(fv, 0.0), 1.0)) / h * math.pi
            phi = ((col + min(max(fu, 0.0), 1.0)) / w - 0.5) * 2.0 * math.pi
            mx = math.sin(theta) * math.sin(phi)
            mz = -math.sin(theta) * math.cos(phi)
            x, z = _rot_y(mx, mz, lp[ENV_ROT])
            d = (x, math.cos(theta), z)
        else:
            ct = 1.0 - 2.0 * u1
            st = math.sqrt(max(1.0 - ct * ct, 0.0))
            phi = 2.0 * math.pi * u2
            d = (st * math.cos(phi), ct, st * math.sin(phi))
    r, g, b, pdf = infinite_radiance_pdf(d, lp, env_img, cdf_rows, cdf_cols)
    if pdf <= 0.0:
        return zero, 0.0, zero, 0.0, -1
    return d, np.inf, (r, g, b), pdf, -1


@njit(cache=True, error_model="numpy")
def sample_delta(u, p, lp):
    """One of the delta lights chosen by ``u`` in [0, 1), as seen from ``p`` (see :func:`sample_light`).

    The radiance returned is ``I f(theta) / dist^2``, Mitsuba's ``spot`` ``sample_direction``.
    """
    zero = (0.0, 0.0, 0.0)
    count = int(lp[N_DELTA])
    j = 0
    while j < count - 1 and u >= lp[N_PARAMS + j * DELTA_STRIDE + D_CDF]:
        j += 1
    b = N_PARAMS + j * DELTA_STRIDE
    prob = lp[b + D_CDF] - (lp[b - DELTA_STRIDE + D_CDF] if j > 0 else 0.0)
    dx, dy, dz = lp[b + D_POS] - p[0], lp[b + D_POS + 1] - p[1], lp[b + D_POS + 2] - p[2]
    d2 = dx * dx + dy * dy + dz * dz
    if not (d2 > 0.0 and prob > 0.0):
        return zero, 0.0, zero, 0.0, -1
    dist = math.sqrt(d2)
    d = (dx / dist, dy / dist, dz / dist)
    m = b + D_TO_LOCAL  # the light's local direction towards p: to_local (-d)
    lx = -(lp[m] * d[0] + lp[m + 1] * d[1] + lp[m + 2] * d[2])
    ly = -(lp[m + 3] * d[0] + lp[m + 4] * d[1] + lp[m + 5] * d[2])
    lz = -(lp[m + 6] * d[0] + lp[m + 7] * d[1] + lp[m + 8] * d[2])
    norm = math.sqrt(lx * lx + ly * ly + lz * lz)
    if not norm > 0.0:
        return zero, 0.0, zero, 0.0, -1
    cos_t = lz / norm
    if not cos_t > lp[b + D_COS_CUTOFF]:
        return zero, 0.0, zero, 0.0, -1
    falloff = 1.0
    if cos_t < lp[b + D_COS_BEAM]:
        falloff = (lp[b + D_CUTOFF] - math.acos(min(cos_t, 1.0))) * lp[b + D_INV_TRANSITION]
    k = falloff / d2
    le = (lp[b + D_INTENSITY] * k, lp[b + D_INTENSITY + 1] * k, lp[b + D_INTENSITY + 2] * k)
    return d, dist, le, lp[P_DELTA] * prob, DELTA_LIGHT


def delta_light_params(lights: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """The ``lp`` entries of delta lights (``Scene.params["delta_lights"]``) and each light's power.

    Each light: ``{"type": "spot", "position": [3], "to_local": [[3] x 3], "intensity": [3],
    "cutoff_angle": degrees, "beam_width": degrees}``.

    Returns
    -------
    block : ndarray (DELTA_STRIDE * len(lights),) float64
        Without the cumulative probabilities (set by the caller from the powers).
    power : ndarray (len(lights),) float64
        ``luminance(I) 2 pi (1 - cos cutoff)``, the flux of a spot without falloff.
    """
    block = np.zeros(DELTA_STRIDE * len(lights))
    power = np.zeros(len(lights))
    for j, light in enumerate(lights):
        b = j * DELTA_STRIDE
        cutoff = math.radians(float(light["cutoff_angle"]))
        beam = min(math.radians(float(light["beam_width"])), cutoff)
        block[b + D_POS:b + D_POS + 3] = light["position"]
        block[b + D_TO_LOCAL:b + D_TO_LOCAL + 9] = np.asarray(light["to_local"], float).reshape(9)
        block[b + D_INTENSITY:b + D_INTENSITY + 3] = light["intensity"]
        block[b + D_COS_CUTOFF] = math.cos(cutoff)
        block[b + D_COS_BEAM] = math.cos(beam)
        block[b + D_CUTOFF] = cutoff
        block[b + D_INV_TRANSITION] = 1.0 / (cutoff - beam) if cutoff > beam else 0.0
        lum = float(np.asarray(light["intensity"], float) @ np.array([0.2126, 0.7152, 0.0722]))
        power[j] = max(lum, 0.0) * 2.0 * math.pi * (1.0 - math.cos(cutoff))
    return block, power


def environment_tables(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cumulative tables for sampling an equirectangular map by luminance x sin(theta).

    Parameters
    ----------
    image : ndarray (h, w, 3) float32

    Returns
    -------
    cdf_rows : ndarray (h + 1,) float64
        Marginal distribution of rows.
    cdf_cols : ndarray (h, w + 1) float64
        Conditional distribution of columns in each row.
    """
    h, w = image.shape[:2]
    lum = luminance_image(image)
    sin_t = np.sin((np.arange(h) + 0.5) / h * np.pi)
    weight = lum * sin_t[:, None]
    weight = weight + 1e-6 * max(float(weight.mean()), 1e-30)
    row_sum = weight.sum(axis=1)
    cdf_cols = np.zeros((h, w + 1))
    cdf_cols[:, 1:] = np.cumsum(weight, axis=1) / row_sum[:, None]
    cdf_cols[:, -1] = 1.0
    cdf_rows = np.zeros(h + 1)
    cdf_rows[1:] = np.cumsum(row_sum) / row_sum.sum()
    cdf_rows[-1] = 1.0
    return cdf_rows, cdf_cols


def luminance_image(image: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance of an (..., 3) linear image, float64, clamped at zero."""
    img = np.asarray(image, np.float64)
    return np.maximum(img @ np.array([0.2126, 0.7152, 0.0722]), 0.0)
