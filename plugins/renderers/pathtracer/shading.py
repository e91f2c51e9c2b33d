"""Textures and material trees at a surface point: what the integrator needs before a BSDF call.

A material is a tree of nodes (see :mod:`.materials`). :func:`resolve` walks it from the root to
one leaf BSDF with Mitsuba's wrapper semantics:

- ``twosided``: the front child where the viewer is on the side of the shading normal, else the
  back child (the same child unless two were given); the leaf is then evaluated with its frame
  turned to the viewer. Without it, a Mitsuba BSDF is black from behind (as in Mitsuba).
- ``mask``: with probability ``1 - opacity`` the surface is passed through (a null interaction),
  else the nested BSDF; ``opacity`` of a colour texture is its luminance (Mitsuba's ``eval_1``).
- ``blendbsdf``: the second child with probability ``weight``, else the first, so that in
  expectation ``f = (1 - weight) f_0 + weight f_1``.
- ``bumpmap``: the nested BSDF, shaded with the normal :func:`bump_normal` makes from the height
  texture's gradient; :func:`bump_shadowing` is the factor Mitsuba 3 applies to the scattered light
  (``docs/pathtracer.md`` has the equations).

One uniform number chooses; it is rescaled at each choice so that nested choices stay uniform.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .bsdf import BLEND, BUMP, F_AU, F_S, I_CHILD0, I_CHILD1, I_TEX_S, MASK, TWOSIDED


@njit(cache=True, error_model="numpy")
def _bilinear(tex_data, k00, k01, k10, k11, fx, fy):
    """Bilinear blend of the texels at flat indices k00 (top left), k01, k10, k11."""
    a00 = tex_data[k00]
    a01 = tex_data[k01]
    a10 = tex_data[k10]
    a11 = tex_data[k11]
    return (1 - fy) * ((1 - fx) * a00 + fx * a01) + fy * ((1 - fx) * a10 + fx * a11)


@njit(cache=True, error_model="numpy", inline="always")
def _wrap(i, n):
    """``i % n`` (Python's, in [0, n)) without the integer division where ``i`` is already in range."""
    if 0 <= i < n:
        return i
    return i % n


@njit(cache=True, error_model="numpy", inline="always")
def tex_rgb(k, u, v, tex_data, tex_off, tex_w, tex_h, tex_uv):
    """Texture ``k`` at harness uv (bilinear, wrapping).

    ``(u, v)`` is scaled and offset by the texture's ``tex_uv`` (``su, sv, ou, ov``); texel (r, c)
    is centred on ``u = (c + 0.5) / w``, ``v = 1 - (r + 0.5) / h``: row 0 at the top, as
    Mitsuba's ``bitmap`` looks up its ``(u, 1 - v)``.
    """
    w = tex_w[k]
    h = tex_h[k]
    off = tex_off[k]
    us = u * tex_uv[k, 0] + tex_uv[k, 2]
    vs = v * tex_uv[k, 1] + tex_uv[k, 3]
    x = (us - math.floor(us)) * w - 0.5
    y = (1.0 - (vs - math.floor(vs))) * h - 0.5
    if not (math.isfinite(x) and math.isfinite(y)):
        return 0.0, 0.0, 0.0
    x0 = math.floor(x)
    y0 = math.floor(y)
    fx = x - x0
    fy = y - y0
    i0 = _wrap(int(x0), w)
    j0 = _wrap(int(y0), h)
    i1 = _wrap(i0 + 1, w)
    j1 = _wrap(j0 + 1, h)
    k00 = off + (j0 * w + i0) * 3
    k01 = off + (j0 * w + i1) * 3
    k10 = off + (j1 * w + i0) * 3
    k11 = off + (j1 * w + i1) * 3
    return (_bilinear(tex_data, k00, k01, k10, k11, fx, fy),
            _bilinear(tex_data, k00 + 1, k01 + 1, k10 + 1, k11 + 1, fx, fy),
            _bilinear(tex_data, k00 + 2, k01 + 2, k10 + 2, k11 + 2, fx, fy))


@njit(cache=True, error_model="numpy", inline="always")
def node_colour(node, tex_slot, column, u, v, nf, ni, tex_data, tex_off, tex_w, tex_h, tex_uv):
    """Colour slot of a node: its constant times its texture (when it has one)."""
    r, g, b = nf[node, column], nf[node, column + 1], nf[node, column + 2]
    k = ni[node, tex_slot]
    if k < 0:
        return r, g, b
    tr, tg, tb = tex_rgb(k, u, v, tex_data, tex_off, tex_w, tex_h, tex_uv)
    return r * tr, g * tg, b * tb


@njit(cache=True, error_model="numpy", inline="always")
def node_scalar(node, u, v, nf, ni, tex_data, tex_off, tex_w, tex_h, tex_uv):
    """The scalar slot (opacity, blend weight): the constant, or the texture's luminance."""
    r, g, b = node_colour(node, I_TEX_S, F_S, u, v, nf, ni, tex_data, tex_off, tex_w, tex_h, tex_uv)
    if ni[node, I_TEX_S] < 0:
        return r
    return 0.2126 * r + 0.7152 * g + 0.0722 * b


@njit(cache=True, error_model="numpy")
def resolve(root, front, u_sel, u, v, node_kind, nf, ni, tex_data, tex_off, tex_w, tex_h, tex_uv):
    """The leaf BSDF chosen at a surface point.

    Returns
    -------
    leaf : int
        Node of the BSDF (-1: passed through a mask).
    two_sided : bool
        Whether a ``twosided`` wrapper holds the leaf.
    bump : int
        The ``bumpmap`` node on the way (the innermost one), or -1.
    bump_outside : bool
        Whether that ``bumpmap`` holds the ``twosided`` wrapper (rather than the reverse).
    """
    node = root
    two_sided = False
    bump = -1
    bump_outside = False
    for _ in range(16):
        kind = node_kind[node]
        if kind == TWOSIDED:
            two_sided = True
            node = ni[node, I_CHILD0] if front else ni[node, I_CHILD1]
        elif kind == MASK:
            o = node_scalar(node, u, v, nf, ni, tex_data, tex_off, tex_w, tex_h, tex_uv)
            if not u_sel < o:
                return -1, two_sided, bump, bump_outside
            u_sel = u_sel / o
            node = ni[node, I_CHILD0]
        elif kind == BLEND:
            w = min(max(node_scalar(node, u, v, nf, ni, tex_data, tex_off, tex_w, tex_h, tex_uv), 0.0), 1.0)
            if u_sel < w:
                u_sel = u_sel / w
                node = ni[node, I_CHILD1]
            else:
                u_sel = (u_sel - w) / (1.0 - w) if w < 1.0 else 0.0
                node = ni[node, I_CHILD0]
        elif kind == BUMP:
            bump = node
            bump_outside = not two_sided
            node = ni[node, I_CHILD0]
        else:
            return node, two_sided, bump, bump_outside
    return node, two_sided, bump, bump_outside


@njit(cache=True, error_model="numpy")
def tex_gradient(k, u, v, tex_data, tex_off, tex_w, tex_h, tex_uv):
    """Gradient ``(dH/du, dH/dv)`` in harness uv of texture ``k``'s luminance ``H``, bilinearly
    interpolated as :func:`tex_rgb` reads it (the derivative of the bilinear blend, times the
    texel counts and the uv scale: Mitsuba's ``eval_1_grad`` of a bitmap)."""
    w = tex_w[k]
    h = tex_h[k]
    off = tex_off[k]
    us = u * tex_uv[k, 0] + tex_uv[k, 2]
    vs = v * tex_uv[k, 1] + tex_uv[k, 3]
    x = (us - math.floor(us)) * w - 0.5
    y = (1.0 - (vs - math.floor(vs))) * h - 0.5
    if not (math.isfinite(x) and math.isfinite(y)):
        return 0.0, 0.0
    x0 = math.floor(x)
    y0 = math.floor(y)
    fx = x - x0
    fy = y - y0
    i0 = _wrap(int(x0), w)
    j0 = _wrap(int(y0), h)
    i1 = _wrap(i0 + 1, w)
    j1 = _wrap(j0 + 1, h)
    a00 = _luminance_at(tex_data, off + (j0 * w + i0) * 3)
    a01 = _luminance_at(tex_data, off + (j0 * w + i1) * 3)
    a10 = _luminance_at(tex_data, off + (j1 * w + i0) * 3)
    a11 = _luminance_at(tex_data, off + (j1 * w + i1) * 3)
    d_fx = (1.0 - fy) * (a01 - a00) + fy * (a11 - a10)
    d_fy = (1.0 - fx) * (a10 - a00) + fx * (a11 - a01)
    # x = frac(us) w - 1/2, y = (1 - frac(vs)) h - 1/2: dx/du = w su, dy/dv = -h sv
    return d_fx * w * tex_uv[k, 0], -d_fy * h * tex_uv[k, 1]


@njit(cache=True, error_model="numpy", inline="always")
def _luminance_at(tex_data, k):
    return 0.2126 * tex_data[k] + 0.7152 * tex_data[k + 1] + 0.0722 * tex_data[k + 2]


@njit(cache=True, error_model="numpy")
def bump_normal(node, mirrored, n, ng, wo, tri, u, v, tri_v, tri_uv, nf, ni, tex_data, tex_off, tex_w, tex_h,
                tex_uv):
    """The shading normal of ``bumpmap`` node ``node`` at a point of triangle ``tri``.

    ``mirrored``: the bump of the opposite frame, negated (``-bump(-n)``), for a ``bumpmap``
    holding a ``twosided`` seen from behind (see ``docs/pathtracer.md``); else :func:`_bump`.
    """
    if mirrored:
        b = _bump(node, (-n[0], -n[1], -n[2]), ng, wo, tri, u, v, tri_v, tri_uv, nf, ni, tex_data, tex_off, tex_w,
                  tex_h, tex_uv)
        return -b[0], -b[1], -b[2]
    return _bump(node, n, ng, wo, tri, u, v, tri_v, tri_uv, nf, ni, tex_data, tex_off, tex_w, tex_h, tex_uv)


@njit(cache=True, error_model="numpy")
def _bump(node, n, ng, wo, tri, u, v, tri_v, tri_uv, nf, ni, tex_data, tex_off, tex_w, tex_h, tex_uv):
    """Mitsuba 3's bump-mapped shading normal at a point of triangle ``tri``.

    With the triangle's ``dp/du``, ``dp/dv`` and the scaled height gradient ``(g_u, g_v)``:
    ``dp/du' = dp/du + n (g_u - <n, dp/du>)`` (likewise for v), ``n_b = normalize(dp/du' x dp/dv')``
    turned to the side of ``ng``; where the viewer ``wo`` lies on different sides of ``n`` and ``n_b``,
    ``n_b``'s tangential part is mirrored (``2 <n_b, n> n - n_b``, Mitsuba's ``flip_invalid_normals``).

    Parameters
    ----------
    node : int
    n, ng : 3-tuples
        Unit shading and geometric normals (``ng`` is turned to ``n``'s side here).
    wo : 3-tuple
        Unit direction towards the viewer.
    tri : int
    u, v : float
        Harness uv of the point.
    """
    k = ni[node, I_TEX_S]
    if k < 0:
        return n
    gu, gv = tex_gradient(k, u, v, tex_data, tex_off, tex_w, tex_h, tex_uv)
    gu *= nf[node, F_AU]
    gv *= nf[node, F_AU]
    e1 = (np.float64(tri_v[tri, 3]) - tri_v[tri, 0], np.float64(tri_v[tri, 4]) - tri_v[tri, 1],
          np.float64(tri_v[tri, 5]) - tri_v[tri, 2])
    e2 = (np.float64(tri_v[tri, 6]) - tri_v[tri, 0], np.float64(tri_v[tri, 7]) - tri_v[tri, 1],
          np.float64(tri_v[tri, 8]) - tri_v[tri, 2])
    du1 = np.float64(tri_uv[tri, 2]) - tri_uv[tri, 0]
    dv1 = np.float64(tri_uv[tri, 3]) - tri_uv[tri, 1]
    du2 = np.float64(tri_uv[tri, 4]) - tri_uv[tri, 0]
    dv2 = np.float64(tri_uv[tri, 5]) - tri_uv[tri, 1]
    det = du1 * dv2 - dv1 * du2
    if not (det != 0.0 and math.isfinite(det)):
        return n
    inv = 1.0 / det
    dpdu = ((dv2 * e1[0] - dv1 * e2[0]) * inv, (dv2 * e1[1] - dv1 * e2[1]) * inv, (dv2 * e1[2] - dv1 * e2[2]) * inv)
    dpdv = ((du1 * e2[0] - du2 * e1[0]) * inv, (du1 * e2[1] - du2 * e1[1]) * inv, (du1 * e2[2] - du2 * e1[2]) * inv)
    a = gu - (n[0] * dpdu[0] + n[1] * dpdu[1] + n[2] * dpdu[2])
    b = gv - (n[0] * dpdv[0] + n[1] * dpdv[1] + n[2] * dpdv[2])
    pu = (dpdu[0] + n[0] * a, dpdu[1] + n[1] * a, dpdu[2] + n[2] * a)
    pv = (dpdv[0] + n[0] * b, dpdv[1] + n[1] * b, dpdv[2] + n[2] * b)
    c = (pu[1] * pv[2] - pu[2] * pv[1], pu[2] * pv[0] - pu[0] * pv[2], pu[0] * pv[1] - pu[1] * pv[0])
    side = 1.0 if ng[0] * n[0] + ng[1] * n[1] + ng[2] * n[2] >= 0.0 else -1.0
    if side * (ng[0] * c[0] + ng[1] * c[1] + ng[2] * c[2]) < 0.0:
        c = (-c[0], -c[1], -c[2])
    if (wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2]) * (wo[0] * c[0] + wo[1] * c[1] + wo[2] * c[2]) <= 0.0:
        cn = 2.0 * (c[0] * n[0] + c[1] * n[1] + c[2] * n[2])
        c = (cn * n[0] - c[0], cn * n[1] - c[1], cn * n[2] - c[2])
    length = math.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
    if not (length > 0.0 and math.isfinite(length)):
        return n
    return c[0] / length, c[1] / length, c[2] / length


@njit(cache=True, error_model="numpy")
def bump_shadowing(n, nb, w):
    """Factor on light scattered along ``w`` by a bump-mapped BSDF of normal ``nb`` over ``n``.

    0 where ``w`` lies on different sides of ``n`` and ``nb`` (Mitsuba's bumpmap makes such light
    black); else the shadowing of Estevez et al. (Ray Tracing Gems, 2019) that Mitsuba 3 applies,
    ``2 / (1 + sqrt(1 + a^2 tan^2 theta_w))`` with ``a^2 = min(tan^2 theta_b / 8, 1)``, both angles
    measured from ``n``.
    """
    cw = w[0] * n[0] + w[1] * n[1] + w[2] * n[2]
    if cw * (w[0] * nb[0] + w[1] * nb[1] + w[2] * nb[2]) <= 0.0:
        return 0.0
    cb = nb[0] * n[0] + nb[1] * n[1] + nb[2] * n[2]
    a2 = min(0.125 * (1.0 - cb * cb) / (cb * cb), 1.0) if cb * cb > 0.0 else 1.0
    return 2.0 / (1.0 + math.sqrt(1.0 + a2 * max(1.0 - cw * cw, 0.0) / (cw * cw)))


@njit(cache=True, error_model="numpy")
def transparent(root, front, u, v, node_kind, nf, ni, tex_data, tex_off, tex_w, tex_h, tex_uv):
    """True where the material's (first) mask has opacity 0: no sample can stop here."""
    node = root
    for _ in range(16):
        kind = node_kind[node]
        if kind == TWOSIDED:
            node = ni[node, I_CHILD0] if front else ni[node, I_CHILD1]
        elif kind == MASK:
            return node_scalar(node, u, v, nf, ni, tex_data, tex_off, tex_w, tex_h, tex_uv) <= 0.0
        elif kind == BUMP:
            node = ni[node, I_CHILD0]
        else:
            return False
    return False


@njit(cache=True, error_model="numpy", inline="always")
def albedo_at(m, u, v, base, gbuffer_tex, tex_data, tex_off, tex_w, tex_h, tex_uv):
    """``base[m]`` times material ``m``'s albedo texture (the G-buffer's albedo channel)."""
    r, g, b = np.float64(base[m, 0]), np.float64(base[m, 1]), np.float64(base[m, 2])
    k = gbuffer_tex[m]
    if k < 0:
        return r, g, b
    tr, tg, tb = tex_rgb(k, u, v, tex_data, tex_off, tex_w, tex_h, tex_uv)
    return r * tr, g * tg, b * tb
