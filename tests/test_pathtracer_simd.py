"""Path tracer SIMD traversal: the 8-lane box test against a float64 oracle, wide-BVH queries
against brute force on axis-aligned geometry (grazing and axis-parallel rays)."""

from __future__ import annotations

import numpy as np
from numba import njit

from plugins.renderers.pathtracer.bvh import ROOT, UNIT, build_bvh, pack_wide
from plugins.renderers.pathtracer.simd import box4, box8, lowest_bit
from plugins.renderers.pathtracer.traverse import _pick, _shear, _triangle, closest_hit, occluded, ray_setup, stack_size


@njit(cache=True)
def _box8(nodes_f, o, d, tmax, near):
    ray, cols = ray_setup(o[0], o[1], o[2], d[0], d[1], d[2], tmax)
    return box8(nodes_f, 0, ray, cols, near, 0)


@njit(cache=True)
def _box4(nodes_f, o, d, tmax, near):
    ray, cols = ray_setup(o[0], o[1], o[2], d[0], d[1], d[2], tmax)
    return box4(nodes_f, 0, ray, cols, near, 0)


@njit(cache=True)
def _bits(mask):
    out = np.zeros(8, np.bool_)
    while mask != 0:
        out[lowest_bit(mask)] = True
        mask &= mask - 1
    return out


@njit(cache=True)
def _brute(o, d, tri_v):
    """Nearest t over every triangle with the traversal's own watertight test (inf for none)."""
    kx, ky, kz, sx, sy, sz = _shear(d[0], d[1], d[2])
    px, py, pz = _pick(o[0], o[1], o[2], kx), _pick(o[0], o[1], o[2], ky), _pick(o[0], o[1], o[2], kz)
    best = np.inf
    for i in range(tri_v.shape[0]):
        t, _, _ = _triangle(tri_v, i, px, py, pz, kx, ky, kz, sx, sy, sz, best)
        best = min(best, t)
    return best


def _row(lo, hi):
    """One node row holding up to 8 boxes (float32); the other lanes empty."""
    row = np.zeros((1, 64), np.float32)
    row[0, :24] = np.inf
    row[0, 24:48] = -np.inf
    for k in range(len(lo)):
        for a in range(3):
            row[0, 8 * a + k] = lo[k][a]
            row[0, 24 + 8 * a + k] = hi[k][a]
    return row


def _unit(lo, hi):
    """One 4-wide node unit holding up to 4 boxes (float32); the other lanes empty."""
    unit = np.zeros((1, UNIT), np.float32)
    unit[0, :12] = np.inf
    unit[0, 12:24] = -np.inf
    for k in range(len(lo)):
        for a in range(3):
            unit[0, 4 * a + k] = lo[k][a]
            unit[0, 12 + 4 * a + k] = hi[k][a]
    return unit


def _leaf_codes(nodes_i):
    """Codes of the leaves reached from the root of :func:`pack_wide`'s nodes (8- and 4-wide)."""
    flat = nodes_i.ravel()
    todo, leaves = [ROOT], []
    while todo:
        code = todo.pop()
        start = (code >> 1) * UNIT
        codes = flat[start + 48:start + 56] if code & 1 else flat[start + 24:start + 28]
        todo += [int(c) for c in codes if c >= 0]
        leaves += [int(c) for c in codes if c < 0]
    return np.array(leaves)


def _oracle(lo, hi, o, d, tmax):
    """Closed-box slab test in float64: (hit, entry distance) per box; a zero direction component
    keeps the box iff the origin lies in the closed slab."""
    hits, nears = [], []
    for b0, b1 in zip(lo, hi):
        near, far = 0.0, tmax
        for a in range(3):
            lo_a, hi_a = float(b0[a]), float(b1[a])
            if d[a] == 0.0:
                if not lo_a <= o[a] <= hi_a:
                    near, far = np.inf, -np.inf
                continue
            t0, t1 = (lo_a - o[a]) / d[a], (hi_a - o[a]) / d[a]
            near, far = max(near, min(t0, t1)), min(far, max(t0, t1))
        hits.append(near <= far)
        nears.append(near)
    return np.array(hits), np.array(nears)


def _check(lo, hi, o, d, tmax, loose=1e-5):
    """box8 reports every box the oracle hits, with an entry distance no later than the exact one,
    and nothing the oracle misses on boxes enlarged by ``loose`` (relative to the scene size);
    box4 gives box8's answer on up to 4 boxes."""
    near = np.empty(8, np.float32)
    got = _bits(_box8(_row(lo, hi), np.asarray(o, np.float64), np.asarray(d, np.float64), tmax, near))
    want, t_exact = _oracle(lo, hi, o, d, tmax)
    n = len(lo)
    assert not got[n:].any(), "an empty lane was hit"
    missed = want & ~got[:n]
    assert not missed.any(), f"box8 missed boxes {np.flatnonzero(missed)} for o={o} d={d}"
    for k in np.flatnonzero(want):
        assert near[k] <= t_exact[k] * (1 + 1e-6) + 1e-30
    pad = loose * 10.0
    big, _ = _oracle([np.asarray(b) - pad for b in lo], [np.asarray(b) + pad for b in hi], o, d, tmax)
    assert not (got[:n] & ~big).any(), "box8 reported a box far from the ray"
    if n <= 4:  # box4 on a 4-wide unit: the same lanes, bit for bit
        near4 = np.empty(8, np.float32)
        got4 = _bits(_box4(_unit(lo, hi), np.asarray(o, np.float64), np.asarray(d, np.float64), tmax, near4))
        assert (got4 == np.concatenate([got[:4], np.zeros(4, np.bool_)])).all()
        k = np.flatnonzero(got[:4])
        assert (near4[k] == near[k]).all()
    return got[:n], want


def test_box8_matches_float64_oracle_on_random_rays():
    rng = np.random.default_rng(7)
    agree = 0
    for _ in range(3000):
        n = int(rng.integers(1, 9))
        c = rng.uniform(-5, 5, (n, 3))
        e = rng.uniform(0.01, 2, (n, 3))
        lo = (c - e).astype(np.float32)
        hi = (c + e).astype(np.float32)
        o = rng.uniform(-8, 8, 3)
        d = rng.normal(size=3)
        tmax = np.inf if rng.random() < 0.5 else float(rng.uniform(0, 15))
        got, want = _check(list(lo), list(hi), o, d, tmax)
        agree += (got == want).all()
    assert agree > 2900  # conservative, but only at the edges


def test_box8_rays_through_corners_and_along_faces():
    """Rays through a box corner (entry = exit up to float64 rounding) and rays leaving a face
    plane at a tiny angle from an origin float32 cannot represent: where float32 arithmetic
    without outward rounding would lose the box."""
    rng = np.random.default_rng(11)
    for _ in range(2000):
        c = rng.uniform(-3, 3, 3)
        e = rng.uniform(0.1, 2, 3)
        lo, hi = (c - e).astype(np.float32), (c + e).astype(np.float32)
        corner = np.where(rng.random(3) < 0.5, lo, hi).astype(np.float64)
        d = rng.normal(size=3)
        o = corner - rng.uniform(0.5, 5) * d  # passes through the corner
        _check([lo], [hi], o, d, np.inf)
        # along face a = hi[a], just inside it, slowly leaving it
        a = int(rng.integers(3))
        o = rng.uniform(lo, hi).astype(np.float64)
        o[a] = float(hi[a]) - rng.uniform(1e-9, 1e-7) * max(1.0, abs(float(hi[a])))
        b = (a + 1) % 3
        o[b] = float(lo[b]) - rng.uniform(0.5, 2.0)
        d = np.zeros(3)
        d[b] = 1.0
        d[a] = (float(hi[a]) - o[a]) / rng.uniform(0.3, 1.0) / (float(hi[b]) - o[b])  # exits inside
        _check([lo], [hi], o, d, np.inf)


def test_box8_grazing_and_axis_parallel_rays():
    lo = [np.array([0, 0, 0], np.float32), np.array([1, 0, 0], np.float32), np.array([-3, -3, 2], np.float32)]
    hi = [np.array([1, 1, 1], np.float32), np.array([2, 1, 1], np.float32), np.array([-2, -2, 3], np.float32)]
    cases = []
    # in a face plane, parallel to it (zero direction components), inside and on the edges
    for y in (0.0, 0.5, 1.0):
        cases.append(((-1.0, y, 1.0), (1.0, 0.0, 0.0)))   # along the top faces z = 1
        cases.append(((-1.0, 1.0, y), (1.0, 0.0, 0.0)))   # along the faces y = 1
        cases.append(((y, -1.0, 0.0), (0.0, 1.0, 0.0)))   # along the bottom faces z = 0
        cases.append(((0.0, y, 5.0), (0.0, 0.0, -1.0)))   # down the faces x = 0
    # through edges and corners, diagonally; along a shared face x = 1 of two boxes
    cases += [((-1.0, -1.0, 0.5), (1.0, 1.0, 0.0)), ((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0)),
              ((2.0, 2.0, 2.0), (-1.0, -1.0, -1.0)), ((1.0, 0.5, 5.0), (0.0, 0.0, -1.0)),
              ((1.0, 0.5, 0.5), (0.0, 0.0, 0.0)), ((-2.5, -2.5, 0.0), (0.0, 0.0, 1.0)),
              ((-3.0, -1.0, 2.5), (0.0, -1.0, 0.0)), ((1e-30, 0.5, 0.5), (-1e-30, 0.0, 1.0))]
    # just outside a face, parallel to it: must miss (beyond the rounding margin)
    misses = [((-1.0, 0.5, 1.001), (1.0, 0.0, 0.0)), ((-1.0, 1.001, 0.5), (1.0, 0.0, 0.0)),
              ((0.5, 0.5, -0.001), (1.0, 1.0, 0.0))]
    for o, d in cases + misses:
        for tmax in (np.inf, 10.0, 0.5):
            _check(lo, hi, np.array(o), np.array(d), tmax)
    for o, d in misses:
        got, _ = _check(lo, hi, np.array(o), np.array(d), np.inf)
        assert not got.any()


def _cube_grid(n):
    """Triangles of the unit cubes of an n x n x n grid (12 each), sharing faces and edges."""
    quads = [((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)), ((0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)),
             ((0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)), ((0, 1, 0), (1, 1, 0), (1, 1, 1), (0, 1, 1)),
             ((0, 0, 0), (0, 1, 0), (0, 1, 1), (0, 0, 1)), ((1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1))]
    tris = []
    for i in range(n):
        for j in range(n):
            for k in range(n):
                base = np.array([i, j, k], np.float64) * 1.5
                for q in quads:
                    q = [base + np.array(p) for p in q]
                    tris += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
    return np.array(tris, np.float32)


def test_wide_bvh_matches_brute_force_on_axis_aligned_geometry():
    """Axis-parallel rays through faces, along edges and in face planes of a grid of cubes:
    closest hit and any hit agree with an exhaustive test of every triangle."""
    verts = _cube_grid(4)
    bounds, child, count, order, depth = build_bvh(verts)
    nodes_f, nodes_i = pack_wide(bounds, child, count)
    assert nodes_f.shape[1] == 32 and nodes_f.ctypes.data % 64 == 0
    leaves = _leaf_codes(nodes_i)
    assert ((-1 - leaves) & 63).sum() == len(verts)  # every triangle in exactly one leaf
    tri_v = np.ascontiguousarray(verts[order].reshape(-1, 9))
    sn, st = np.empty(stack_size(depth), np.int32), np.empty(stack_size(depth), np.float32)
    rng = np.random.default_rng(3)
    hits = 0
    grid = np.array([0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.5, 5.5])
    for _ in range(600):
        axis = int(rng.integers(3))
        o = rng.choice(grid, 3)
        o[axis] = -1.0 if rng.random() < 0.5 else 7.0
        d = np.zeros(3)
        d[axis] = 1.0 if o[axis] < 0 else -1.0
        if rng.random() < 0.3:  # a tilted ray through the same point
            d[(axis + 1) % 3] = rng.choice([0.25, -0.5])
        k, t, _, _ = closest_hit(*o, *d, np.inf, -1, tri_v, nodes_f, nodes_i, sn, st)
        tb = _brute(o, d, tri_v)
        assert (k >= 0) == np.isfinite(tb)
        if k >= 0:
            hits += 1
            assert t == tb
        assert occluded(*o, *d, np.inf, -1, tri_v, nodes_f, nodes_i, sn, st) == (k >= 0)
        if k >= 0:
            assert not occluded(*o, *d, t * (1 - 1e-9), -1, tri_v, nodes_f, nodes_i, sn, st)
    assert hits > 200


def test_wide_nodes_hold_their_children_by_decreasing_box_area():
    """The lanes of every wide node (8- and 4-wide) are ordered by decreasing box area, so that an
    any-hit query, which visits the lowest lane it hits first, tries the largest box first."""
    rng = np.random.default_rng(4)
    centres = rng.random((1500, 1, 3)) * rng.choice([1.0, 10.0], (1500, 1, 1))
    verts = (centres + rng.normal(size=(1500, 3, 3)) * 0.2).astype(np.float32)
    bounds, child, count, order, depth = build_bvh(verts)
    nodes_f, nodes_i = pack_wide(bounds, child, count)
    flat_f, flat_i = nodes_f.ravel().astype(np.float64), nodes_i.ravel()
    todo, nodes, lanes_seen = [ROOT], 0, 0
    while todo:
        code = todo.pop()
        width = 8 if code & 1 else 4
        start = (code >> 1) * UNIT
        codes = flat_i[start + 6 * width:start + 7 * width]
        used = np.flatnonzero(codes != -1)
        planes = flat_f[start:start + 6 * width].reshape(6, width)[:, used]
        d = planes[3:] - planes[:3]
        area = d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
        assert (np.diff(area) <= 0).all()
        assert (used == np.arange(len(used))).all()  # the empty lanes come last
        todo += [int(c) for c in codes if c >= 0]
        nodes += 1
        lanes_seen += len(used)
    assert nodes > 100 and lanes_seen > 2 * nodes
