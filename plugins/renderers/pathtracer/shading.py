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
- ``bumpmap``: the nested BSDF (the height texture is not applied; the loader warns).

One uniform number chooses; it is rescaled at each choice so that nested choices stay uniform.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .bsdf import BLEND, BUMP, F_S, I_CHILD0, I_CHILD1, I_TEX_S, MASK, TWOSIDED


@njit(cache=True, error_model="numpy")
def _bilinear(tex_data, k00, k01, k10, k11, fx, fy):
    """Bilinear blend of the texels at flat indices k00 (top left), k01, k10, k11."""
    a00 = tex_data[k00]
    a01 = tex_data[k01]
    a10 = tex_data[k10]
    a11 = tex_data[k11]
    return (1 - fy) * ((1 - fx) * a00 + fx * a01) + fy * ((1 - fx) * a10 + fx * a11)


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
    i0 = int(x0) % w
    j0 = int(y0) % h
    i1 = (i0 + 1) % w
    j1 = (j0 + 1) % h
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
    """
    node = root
    two_sided = False
    for _ in range(16):
        kind = node_kind[node]
        if kind == TWOSIDED:
            two_sided = True
            node = ni[node, I_CHILD0] if front else ni[node, I_CHILD1]
        elif kind == MASK:
            o = node_scalar(node, u, v, nf, ni, tex_data, tex_off, tex_w, tex_h, tex_uv)
            if not u_sel < o:
                return -1, two_sided
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
            node = ni[node, I_CHILD0]
        else:
            return node, two_sided
    return node, two_sided


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
