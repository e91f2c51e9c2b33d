"""Ray queries against the BVH: closest hit and any hit (shadow rays).

Traversal is iterative with an explicit stack (near child first, far child pushed with its entry
distance so that it is skipped once a closer hit is known). Each step fetches one 64-byte row that
holds both children's boxes (:func:`.bvh.pack_nodes`) and tests the two boxes with the
precomputed entry planes of the ray; the box and triangle tests are inlined into the loops.
Ray-triangle tests follow the watertight algorithm of Woop, Benthin and Wald (JCGT 2013): the ray
is sheared so that it points along +z, and the 2D edge functions are evaluated in double
precision, so a ray through a shared edge or vertex hits at least one of the triangles that share
it (no cracks between triangles).

Geometry arrays: ``tri_v`` (T, 9) float32 rows ``v0 v1 v2``; ``nodes_f`` and ``nodes_i``, the two
views of :func:`.bvh.pack_nodes`. ``stack_n`` (int32) and ``stack_t`` (float64) are scratch arrays
of at least the tree depth, allocated by the caller (once per group of pixels).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .bvh import LEAF_BITS

INF = np.inf
LEAF_MASK = (1 << LEAF_BITS) - 1


@njit(cache=True, error_model="numpy")
def _pick(x, y, z, k):
    if k == 0:
        return x
    if k == 1:
        return y
    return z


@njit(cache=True, error_model="numpy")
def _inv(d):
    if d != 0.0:
        return 1.0 / d
    return 1e300


@njit(cache=True, error_model="numpy", inline="always")
def _boxes(nodes_f, r, jx, jy, jz, ox, oy, oz, ix, iy, iz, tmax):
    """Entry distances of the ray into the two child boxes of row ``r`` (inf for a miss within tmax).

    ``jx, jy, jz`` are the columns of the planes the ray enters through (the min pair for a
    non-negative inverse direction, the max pair otherwise), so that each slab needs no min/max:
    ``(lo - o) * i <= (hi - o) * i`` holds for ``i > 0`` in floating point too, so the distances
    are exactly those of the two-sided slab test.
    """
    lx0 = (np.float64(nodes_f[r, jx]) - ox) * ix
    rx0 = (np.float64(nodes_f[r, jx + 1]) - ox) * ix
    ly0 = (np.float64(nodes_f[r, jy]) - oy) * iy
    ry0 = (np.float64(nodes_f[r, jy + 1]) - oy) * iy
    lz0 = (np.float64(nodes_f[r, jz]) - oz) * iz
    rz0 = (np.float64(nodes_f[r, jz + 1]) - oz) * iz
    lx1 = (np.float64(nodes_f[r, 6 - jx]) - ox) * ix
    rx1 = (np.float64(nodes_f[r, 7 - jx]) - ox) * ix
    ly1 = (np.float64(nodes_f[r, 10 - jy]) - oy) * iy
    ry1 = (np.float64(nodes_f[r, 11 - jy]) - oy) * iy
    lz1 = (np.float64(nodes_f[r, 14 - jz]) - oz) * iz
    rz1 = (np.float64(nodes_f[r, 15 - jz]) - oz) * iz
    ln = max(lx0, ly0, lz0, 0.0)
    rn = max(rx0, ry0, rz0, 0.0)
    lf = min(lx1, ly1, lz1, tmax) * (1.0 + 1e-12)
    rf = min(rx1, ry1, rz1, tmax) * (1.0 + 1e-12)
    return (ln if ln <= lf else INF), (rn if rn <= rf else INF)


@njit(cache=True, error_model="numpy", inline="always")
def _triangle(tri_v, i, px, py, pz, kx, ky, kz, sx, sy, sz, tmax):
    """Watertight test of triangle ``i`` against a ray from (px, py, pz) (the origin in the
    permuted axes kx, ky, kz); returns (t, b1, b2) with t = inf on a miss."""
    ax = np.float64(tri_v[i, kx]) - px
    ay = np.float64(tri_v[i, ky]) - py
    az = np.float64(tri_v[i, kz]) - pz
    bx = np.float64(tri_v[i, 3 + kx]) - px
    by = np.float64(tri_v[i, 3 + ky]) - py
    bz = np.float64(tri_v[i, 3 + kz]) - pz
    cx = np.float64(tri_v[i, 6 + kx]) - px
    cy = np.float64(tri_v[i, 6 + ky]) - py
    cz = np.float64(tri_v[i, 6 + kz]) - pz
    ax = ax - sx * az
    ay = ay - sy * az
    bx = bx - sx * bz
    by = by - sy * bz
    cx = cx - sx * cz
    cy = cy - sy * cz
    u = cx * by - cy * bx
    v = ax * cy - ay * cx
    w = bx * ay - by * ax
    if (u < 0.0 or v < 0.0 or w < 0.0) and (u > 0.0 or v > 0.0 or w > 0.0):
        return INF, 0.0, 0.0
    det = u + v + w
    if det == 0.0:
        return INF, 0.0, 0.0
    t = (u * (sz * az) + v * (sz * bz) + w * (sz * cz)) / det
    if t <= 0.0 or t >= tmax:
        return INF, 0.0, 0.0
    return t, v / det, w / det


@njit(cache=True, error_model="numpy")
def _shear(dx, dy, dz):
    adx, ady, adz = abs(dx), abs(dy), abs(dz)
    kz = 0
    if ady > adx and ady >= adz:
        kz = 1
    elif adz > adx and adz > ady:
        kz = 2
    kx = (kz + 1) % 3
    ky = (kx + 1) % 3
    dkz = _pick(dx, dy, dz, kz)
    if dkz < 0.0:
        kx, ky = ky, kx
    sx = _pick(dx, dy, dz, kx) / dkz
    sy = _pick(dx, dy, dz, ky) / dkz
    sz = 1.0 / dkz
    return kx, ky, kz, sx, sy, sz


@njit(cache=True, error_model="numpy")
def _setup(dx, dy, dz):
    """Per-ray constants of the box test: inverse direction and entry-plane columns."""
    ix, iy, iz = _inv(dx), _inv(dy), _inv(dz)
    jx = 0 if ix >= 0.0 else 6
    jy = 2 if iy >= 0.0 else 8
    jz = 4 if iz >= 0.0 else 10
    return ix, iy, iz, jx, jy, jz


@njit(cache=True, error_model="numpy")
def closest_hit(ox, oy, oz, dx, dy, dz, tmax, skip, tri_v, nodes_f, nodes_i, stack_n, stack_t):
    """Nearest intersection along a ray.

    Parameters
    ----------
    ox, oy, oz, dx, dy, dz : float
        Origin and direction (need not be unit length; ``t`` is in units of it).
    tmax : float
        Hits at ``t >= tmax`` are ignored.
    skip : int
        Index of a triangle to ignore (the one the ray leaves), or -1.

    Returns
    -------
    tri : int
        Triangle index, -1 for a miss.
    t, b1, b2 : float
        Distance and barycentric weights of corners 1 and 2.
    """
    kx, ky, kz, sx, sy, sz = _shear(dx, dy, dz)
    px, py, pz = _pick(ox, oy, oz, kx), _pick(ox, oy, oz, ky), _pick(ox, oy, oz, kz)
    ix, iy, iz, jx, jy, jz = _setup(dx, dy, dz)
    best = -1
    bb1 = 0.0
    bb2 = 0.0
    node = 0
    sp = 0
    while True:
        if node < 0:
            leaf = -1 - node
            first = leaf >> LEAF_BITS
            for i in range(first, first + (leaf & LEAF_MASK)):
                if i == skip:
                    continue
                t, b1, b2 = _triangle(tri_v, i, px, py, pz, kx, ky, kz, sx, sy, sz, tmax)
                if t < tmax:
                    tmax = t
                    best = i
                    bb1 = b1
                    bb2 = b2
        else:
            tl, tr = _boxes(nodes_f, node, jx, jy, jz, ox, oy, oz, ix, iy, iz, tmax)
            if tl != INF or tr != INF:
                cl = nodes_i[node, 12]
                cr = nodes_i[node, 13]
                if tr == INF:
                    node = cl
                elif tl == INF:
                    node = cr
                elif tl <= tr:
                    stack_n[sp] = cr
                    stack_t[sp] = tr
                    sp += 1
                    node = cl
                else:
                    stack_n[sp] = cl
                    stack_t[sp] = tl
                    sp += 1
                    node = cr
                continue
        while True:
            if sp == 0:
                return best, tmax, bb1, bb2
            sp -= 1
            if stack_t[sp] < tmax:
                node = stack_n[sp]
                break


@njit(cache=True, error_model="numpy")
def occluded(ox, oy, oz, dx, dy, dz, tmax, skip, tri_v, nodes_f, nodes_i, stack_n):
    """True if any triangle other than ``skip`` is hit at ``0 < t < tmax``."""
    kx, ky, kz, sx, sy, sz = _shear(dx, dy, dz)
    px, py, pz = _pick(ox, oy, oz, kx), _pick(ox, oy, oz, ky), _pick(ox, oy, oz, kz)
    ix, iy, iz, jx, jy, jz = _setup(dx, dy, dz)
    node = 0
    sp = 0
    while True:
        if node < 0:
            leaf = -1 - node
            first = leaf >> LEAF_BITS
            for i in range(first, first + (leaf & LEAF_MASK)):
                if i == skip:
                    continue
                t, b1, b2 = _triangle(tri_v, i, px, py, pz, kx, ky, kz, sx, sy, sz, tmax)
                if t < tmax:
                    return True
        else:
            tl, tr = _boxes(nodes_f, node, jx, jy, jz, ox, oy, oz, ix, iy, iz, tmax)
            if tl != INF or tr != INF:
                # the nearer child next, the other one on the stack
                cl = nodes_i[node, 12]
                cr = nodes_i[node, 13]
                if tr == INF:
                    node = cl
                elif tl == INF:
                    node = cr
                elif tl <= tr:
                    stack_n[sp] = cr
                    sp += 1
                    node = cl
                else:
                    stack_n[sp] = cl
                    sp += 1
                    node = cr
                continue
        if sp == 0:
            return False
        sp -= 1
        node = stack_n[sp]
