"""G-buffer channels from the first hits: the same surface points the integrator starts from."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .integrator import surface
from .shading import albedo_at
from .vecmath import dot


@njit(parallel=True, cache=True, error_model="numpy")
def gbuffer(origins, dirs, tri, bary, forward, geom, mats, tri_obj, base, base_tex):
    """Position, shading normal, albedo, depth and object id per pixel.

    The normal is the interpolated shading normal, negated where the back face (by winding) is
    seen, and the albedo channel follows the raster renderer's conventions, so both renderers
    report the same features.

    Parameters
    ----------
    origins, dirs : ndarray (N, 3) float64
    tri, bary : first hits (see :func:`.integrator.first_hits`).
    forward : ndarray (3,) float64
        Unit viewing axis of the camera (depth is measured along it).
    geom, mats : scene arrays.
    tri_obj : ndarray (T,) int32
    base : ndarray (M, 3) float32
        Per-material colour of the albedo channel before texturing (as the raster renderer:
        diffuse albedo; F0 for conductors and mirrors; white for dielectrics).
    base_tex : ndarray (M,) int32
        The texture of each material's albedo (``harness.Material.texture``), -1 for none.

    Returns
    -------
    position, normal, albedo : ndarray (N, 3) float32
    depth : ndarray (N,) float32 (inf for background)
    object_id : ndarray (N,) int32 (-1 for background)
    """
    tri_v, tri_n, tri_uv, tri_mat, nodes_f, nodes_i, tri_front = geom
    mat_root, mat_flags, mat_emit, node_kind, nf, ni, tables, tex_data, tex_off, tex_w, tex_h, tex_uv = mats
    n = origins.shape[0]
    position = np.zeros((n, 3), np.float32)
    normal = np.zeros((n, 3), np.float32)
    albedo = np.zeros((n, 3), np.float32)
    depth = np.full(n, np.inf, np.float32)
    object_id = np.full(n, -1, np.int32)
    for i in prange(n):
        t = tri[i]
        if t < 0:
            continue
        p, ng, ns, u, v = surface(t, bary[i, 0], bary[i, 1], tri_v, tri_n, tri_uv)
        d = (dirs[i, 0], dirs[i, 1], dirs[i, 2])
        if dot(ng, d) > 0.0:  # back face seen: turn the normal to the viewer
            ns = (-ns[0], -ns[1], -ns[2])
        a = albedo_at(tri_mat[t], u, v, base, base_tex, tex_data, tex_off, tex_w, tex_h, tex_uv)
        for c in range(3):
            position[i, c] = p[c]
            normal[i, c] = ns[c]
            albedo[i, c] = a[c]
        depth[i] = (p[0] - origins[i, 0]) * forward[0] + (p[1] - origins[i, 1]) * forward[1] + (
            p[2] - origins[i, 2]) * forward[2]
        object_id[i] = tri_obj[t]
    return position, normal, albedo, depth, object_id
