"""Path tracer geometry: SAH BVH traversal against brute force, watertight triangle tests."""

from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv
from numba import njit

from plugins.renderers.pathtracer.bvh import build_bvh, pack_wide
from plugins.renderers.pathtracer.traverse import closest_hit, occluded, stack_size


def _brute(tri, o, d):
    """Nearest hit of a ray against (T, 3, 3) triangles with a float64 Moeller-Trumbore test."""
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = o - v0
        u = np.einsum("ij,ij->i", s, p) * inv
        q = np.cross(s, e1)
        v = (q @ d) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
    ok = (np.abs(det) > 1e-14) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    t = np.where(ok, t, np.inf)
    k = int(np.argmin(t))
    return (k, t[k]) if np.isfinite(t[k]) else (-1, np.inf)


def _prepare(verts):
    bounds, child, count, order, depth = build_bvh(verts)
    nodes_f, nodes_i = pack_wide(bounds, child, count)
    return verts[order], nodes_f, nodes_i, count, order, depth


def _stacks(depth):
    return np.empty(stack_size(depth), np.int32), np.empty(stack_size(depth), np.float32)


def test_bvh_closest_hit_matches_brute_force():
    rng = np.random.default_rng(1)
    centres = rng.random((3000, 1, 3)) * 10
    verts = (centres + rng.normal(size=(3000, 3, 3)) * 0.3).astype(np.float32)
    ordered, nodes_f, nodes_i, count, order, depth = _prepare(verts)
    tri_v = np.ascontiguousarray(ordered.reshape(-1, 9))
    assert sorted(order.tolist()) == list(range(3000))
    assert count.sum() == 3000  # every triangle in exactly one leaf
    stack_n, stack_t = _stacks(depth)
    tri64 = verts.astype(np.float64)
    hits = 0
    for _ in range(400):
        o = rng.random(3) * 12 - 1
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        k, t, b1, b2 = closest_hit(*o, *d, np.inf, -1, tri_v, nodes_f, nodes_i, stack_n, stack_t)
        kb, tb = _brute(tri64, o, d)
        assert (k >= 0) == (kb >= 0)
        if k >= 0:
            hits += 1
            assert order[k] == kb or abs(t - tb) < 1e-9
            assert abs(t - tb) <= 1e-9 * max(1.0, tb)
            p = tri64[order[k]]
            hit = (1 - b1 - b2) * p[0] + b1 * p[1] + b2 * p[2]
            assert np.allclose(hit, o + t * d, atol=1e-9)
        assert occluded(*o, *d, np.inf, -1, tri_v, nodes_f, nodes_i, stack_n, stack_t) == (kb >= 0)
        if kb >= 0:  # a shadow ray that stops short of the nearest hit is not occluded
            assert not occluded(*o, *d, tb * 0.999, -1, tri_v, nodes_f, nodes_i, stack_n, stack_t)
    assert hits > 50


def test_single_triangle_hit_and_skip():
    verts = np.zeros((1, 3, 3), np.float32)
    verts[0] = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    ordered, nodes_f, nodes_i, count, order, depth = _prepare(verts)
    tri_v = ordered.reshape(-1, 9)
    sn, st = _stacks(depth)
    k, t, _, _ = closest_hit(0.2, 0.2, 1.0, 0.0, 0.0, -1.0, np.inf, -1, tri_v, nodes_f, nodes_i, sn, st)
    assert k == 0 and abs(t - 1.0) < 1e-12
    k, _, _, _ = closest_hit(0.2, 0.2, 1.0, 0.0, 0.0, -1.0, np.inf, 0, tri_v, nodes_f, nodes_i, sn, st)
    assert k == -1  # the skipped triangle is ignored


def test_watertight_closed_mesh_has_no_cracks():
    """Rays from inside a closed mesh aimed exactly at its vertices and edge midpoints all hit."""
    shell = pv.Sphere(radius=1.0, theta_resolution=24, phi_resolution=18).triangulate()
    faces = np.asarray(shell.faces).reshape(-1, 4)[:, 1:]
    verts = np.asarray(shell.points, np.float32)[faces]
    ordered, nodes_f, nodes_i, count, order, depth = _prepare(verts)
    tri_v = np.ascontiguousarray(ordered.reshape(-1, 9))
    sn, st = _stacks(depth)
    targets = np.concatenate([shell.points, 0.5 * (verts[:, 0] + verts[:, 1]), 0.5 * (verts[:, 1] + verts[:, 2])])
    origin = np.array([0.01, -0.02, 0.03])
    misses = 0
    for q in targets.astype(np.float64):
        d = q - origin
        d /= np.linalg.norm(d)
        k, _, _, _ = closest_hit(*origin, *d, np.inf, -1, tri_v, nodes_f, nodes_i, sn, st)
        misses += k < 0
    assert misses == 0


def _function_body(llvm_ir: str, name: str) -> str:
    """The LLVM IR of the defined function whose symbol contains ``name``."""
    start = next(i for i, line in enumerate(llvm_ir.splitlines())
                 if line.startswith("define") and name in line and "cpython" not in line)
    lines = llvm_ir.splitlines()[start:]
    return "\n".join(lines[:lines.index("}") + 1])


@pytest.mark.slow
def test_traversal_has_no_reference_counting():
    """No atomic reference-count updates per ray or per node (see the docstring of ``traverse``).

    Mutation check: with the children's prefetches moved back into an inlined helper taking the
    arrays, both functions call ``NRT_incref`` again. The functions are compiled afresh here
    (same flags, no cache): Numba cannot show the IR of code it loaded from its disk cache."""
    verts = np.zeros((1, 3, 3), np.float32)
    verts[0] = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    ordered, nodes_f, nodes_i, count, order, depth = _prepare(verts)
    tri_v = np.ascontiguousarray(ordered.reshape(-1, 9))
    sn, st = _stacks(depth)
    args = (0.2, 0.2, 1.0, 0.0, 0.0, -1.0, np.inf, -1, tri_v, nodes_f, nodes_i, sn, st)
    for fn, name in ((closest_hit, "closest_hit"), (occluded, "occluded")):
        fresh = njit(error_model="numpy")(fn.py_func)
        fresh(*args)
        for llvm_ir in fresh.inspect_llvm().values():
            body = _function_body(llvm_ir, name)
            assert "NRT_incref" not in body and "NRT_decref" not in body, name
