"""Ray queries against the wide BVH: closest hit and any hit (shadow rays).

Traversal is iterative with an explicit stack. Each step tests the ray against the eight (or, in
a narrow node, four) child boxes of one wide node at once (:func:`.simd.box8`, :func:`.simd.box4`:
packed single-precision SIMD with conservative rounding, so no box the ray meets is missed). A
node's code says which (bit 0, see :func:`.bvh.pack_wide`). Of the children hit, the nearest is
visited next and the others are pushed, farthest deepest (closest hit) so that they are skipped
once a closer hit is known. Ray-triangle tests follow the watertight algorithm of Woop, Benthin
and Wald (JCGT 2013): the ray is sheared so that it points along +z, and the 2D edge functions are
evaluated in double precision, so a ray through a shared edge or vertex hits at least one of the
triangles that share it (no cracks between triangles).

Geometry arrays: ``tri_v`` (T, 9) float32 rows ``v0 v1 v2``; ``nodes_f`` and ``nodes_i``, the two
views of :func:`.bvh.pack_wide`. ``stack_n`` (int32) and ``stack_t`` (float32) are scratch arrays
of at least :func:`stack_size` entries, allocated by the caller (once per thread).

No reference counting: Numba increments and decrements the reference count of an array (an
atomic instruction on a counter that both threads share) where it is passed to an inlined helper
inside these loops, and its pruning pass cannot remove the pairs there. The prefetches of pushed
children are therefore written out in place, not in a helper taking the arrays;
``tests/test_pathtracer_geometry.py::test_traversal_has_no_reference_counting`` checks the
machine code.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .bvh import LEAF_BITS, NARROW, ROOT, UNIT, WIDTH
from .simd import FAR_SCALE, box4, box8, lowest_bit, prefetch

INF = np.inf
LEAF_MASK = (1 << LEAF_BITS) - 1
CODES8 = 6 * WIDTH - UNIT  # column of the child codes of an 8-wide node, in its second unit
CODES4 = 6 * NARROW  # the same in a 4-wide node's unit
F32_INF = np.float32(np.inf)
WIDEN = 2.0**-22  # relative outward shift of rounded origins: at least 1.5 float32 ulps after rounding
TINY = 2.0**-126  # the same near 0 (the smallest normal float32)


@njit(cache=True, error_model="numpy")
def stack_size(depth):
    """Stack entries that traversal of a tree of ``depth`` binary levels needs (plus the 8-lane
    scratch that :func:`.simd.box8` writes above the top)."""
    return (WIDTH - 1) * depth + WIDTH + 1


@njit(cache=True, error_model="numpy")
def _pick(x, y, z, k):
    if k == 0:
        return x
    if k == 1:
        return y
    return z


@njit(cache=True, error_model="numpy", inline="always")
def _up(x):
    """A float32 above ``x`` (float64), by 1.5 to 4.5 float32 ulps (2**-126 above 0)."""
    return np.float32(x + (abs(x) * WIDEN + TINY))


@njit(cache=True, error_model="numpy", inline="always")
def _down(x):
    """A float32 below ``x`` (float64), by 1.5 to 4.5 float32 ulps (2**-126 below 0)."""
    return np.float32(x - (abs(x) * WIDEN + TINY))


@njit(cache=True, error_model="numpy", inline="always")
def _axis(o, d):
    """Near-plane origin, far-plane origin, inverse direction and near-plane offset of one axis."""
    if d == 0.0:
        return _up(o), _down(o), F32_INF, 0
    inv = np.float32(1.0 / d)
    if d > 0.0:
        return _up(o), _down(o), inv, 0
    return _down(o), _up(o), inv, 3 * WIDTH


@njit(cache=True, error_model="numpy", inline="always")
def ray_setup(ox, oy, oz, dx, dy, dz, tmax):
    """Per-ray constants of :func:`.simd.box8`: the float32 tuple and the near-plane columns."""
    nx, fx, ix, cx = _axis(ox, dx)
    ny, fy, iy, cy = _axis(oy, dy)
    nz, fz, iz, cz = _axis(oz, dz)
    return (nx, ny, nz, fx, fy, fz, ix, iy, iz, _up(tmax) if tmax < INF else F32_INF), (cx, WIDTH + cy,
                                                                                       2 * WIDTH + cz)


@njit(cache=True, error_model="numpy", inline="always")
def _with_tmax(ray, tmax):
    """The tuple of :func:`ray_setup` with a new (closer) ``tmax``."""
    return (ray[0], ray[1], ray[2], ray[3], ray[4], ray[5], ray[6], ray[7], ray[8], _up(tmax))


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


@njit(cache=True, error_model="numpy", inline="always")
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
    ray, cols = ray_setup(ox, oy, oz, dx, dy, dz, tmax)
    cull = ray[9] * np.float32(FAR_SCALE)  # children entered beyond this hold no closer hit
    best = -1
    bb1 = 0.0
    bb2 = 0.0
    node = ROOT
    sp = 0
    while True:
        if node >= 0:
            unit = node >> 1
            if node & 1:
                mask = box8(nodes_f, unit, ray, cols, stack_t, sp)
                crow, ccol = unit + 1, CODES8
            else:
                mask = box4(nodes_f, unit, ray, cols, stack_t, sp)
                crow, ccol = unit, CODES4
            if mask != 0:
                k = lowest_bit(mask)
                mask &= mask - 1
                if mask == 0:
                    node = nodes_i[crow, ccol + k]
                    continue
                # push the children hit (distances compacted down from box8's scratch), nearest on top
                ck = nodes_i[crow, ccol + k]
                if ck >= 0:  # ask for the child's node (2 or 4 lines), or its leaf's first triangles
                    prefetch(nodes_f, ck >> 1, 2)
                    if ck & 1:
                        prefetch(nodes_f, (ck >> 1) + 1, 2)
                else:
                    prefetch(tri_v, (-1 - ck) >> LEAF_BITS, 2)
                stack_n[sp] = ck
                stack_t[sp] = stack_t[sp + k]
                top = sp + 1
                while mask != 0:
                    k = lowest_bit(mask)
                    mask &= mask - 1
                    tk = stack_t[sp + k]
                    ck = nodes_i[crow, ccol + k]
                    if ck >= 0:  # ask for the child's node (2 or 4 lines), or its leaf's first triangles
                        prefetch(nodes_f, ck >> 1, 2)
                        if ck & 1:
                            prefetch(nodes_f, (ck >> 1) + 1, 2)
                    else:
                        prefetch(tri_v, (-1 - ck) >> LEAF_BITS, 2)
                    j = top
                    while j > sp and stack_t[j - 1] < tk:
                        stack_t[j] = stack_t[j - 1]
                        stack_n[j] = stack_n[j - 1]
                        j -= 1
                    stack_t[j] = tk
                    stack_n[j] = ck
                    top += 1
                sp = top - 1
                node = stack_n[sp]
                continue
        else:
            leaf = -1 - node
            first = leaf >> LEAF_BITS
            found = False
            for i in range(first, first + (leaf & LEAF_MASK)):
                if i == skip:
                    continue
                t, b1, b2 = _triangle(tri_v, i, px, py, pz, kx, ky, kz, sx, sy, sz, tmax)
                if t < tmax:
                    tmax = t
                    best = i
                    bb1 = b1
                    bb2 = b2
                    found = True
            if found:
                ray = _with_tmax(ray, tmax)
                cull = ray[9] * np.float32(FAR_SCALE)
        while True:
            if sp == 0:
                return best, tmax, bb1, bb2
            sp -= 1
            if stack_t[sp] <= cull:
                node = stack_n[sp]
                break


@njit(cache=True, error_model="numpy")
def occluded(ox, oy, oz, dx, dy, dz, tmax, skip, tri_v, nodes_f, nodes_i, stack_n, stack_t):
    """True if any triangle other than ``skip`` is hit at ``0 < t < tmax``."""
    kx, ky, kz, sx, sy, sz = _shear(dx, dy, dz)
    px, py, pz = _pick(ox, oy, oz, kx), _pick(ox, oy, oz, ky), _pick(ox, oy, oz, kz)
    ray, cols = ray_setup(ox, oy, oz, dx, dy, dz, tmax)
    node = ROOT
    sp = 0
    while True:
        if node >= 0:
            unit = node >> 1
            if node & 1:
                mask = box8(nodes_f, unit, ray, cols, stack_t, sp)
                crow, ccol = unit + 1, CODES8
            else:
                mask = box4(nodes_f, unit, ray, cols, stack_t, sp)
                crow, ccol = unit, CODES4
            if mask != 0:
                k = lowest_bit(mask)
                mask &= mask - 1
                node = nodes_i[crow, ccol + k]
                while mask != 0:  # the others on the stack, in lane order
                    k = lowest_bit(mask)
                    mask &= mask - 1
                    ck = nodes_i[crow, ccol + k]
                    if ck >= 0:  # ask for the child's node (2 or 4 lines), or its leaf's first triangles
                        prefetch(nodes_f, ck >> 1, 2)
                        if ck & 1:
                            prefetch(nodes_f, (ck >> 1) + 1, 2)
                    else:
                        prefetch(tri_v, (-1 - ck) >> LEAF_BITS, 2)
                    stack_n[sp] = ck
                    sp += 1
                continue
        else:
            leaf = -1 - node
            first = leaf >> LEAF_BITS
            for i in range(first, first + (leaf & LEAF_MASK)):
                if i == skip:
                    continue
                t, b1, b2 = _triangle(tri_v, i, px, py, pz, kx, ky, kz, sx, sy, sz, tmax)
                if t < tmax:
                    return True
        if sp == 0:
            return False
        sp -= 1
        node = stack_n[sp]
