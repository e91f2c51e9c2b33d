"""Ray queries of the ``pathtracer`` alone: closest hit and any hit on rays of a real scene.

Usage::

    NUMBA_NUM_THREADS=1 python benchmarks/bench_traversal.py [--scene classroom] [--rays 200000]
                                                             [--repeats 4] [--baseline REV]

Three ray sets from the first hits of the scene's camera at 1280x720 (pixels drawn at random):
``primary`` (the camera rays), ``bounce`` (from the first hit, offset as the integrator does, in a
cosine-distributed direction around the geometric normal turned to the camera) and ``shadow``
(any-hit queries from the same points, half towards the sun, half in random directions of the
upper hemisphere, unbounded). Each set is traced in a single-threaded loop; the figure is rays
per CPU-second (median and range of ``--repeats`` passes after one warm-up pass, the versions
and sets taking turns call by call: :func:`harness.timer.alternate`). Also printed:
the same bounce rays when only 64 distinct rays are repeated (``resident``, the tree's paths then
stay in cache), which bounds what memory latency costs.

``--baseline REV``: the traversal and BVH as they were at git revision REV (imported beside
ours: ``benchmarks/common.py``) on the same rays, alternating with ours call by call; the hit
counts of the two must agree.
"""

from __future__ import annotations

import importlib
import statistics
from contextlib import nullcontext

import numpy as np
from bench_pathtracer import SCENES, harness_scene
from common import alternate, baseline_package, integer, parser, run
from numba import njit

from harness import load_plugins


def kernels(module):
    """Single-threaded loops over a ray set for one traversal module."""
    closest_hit, occluded, stack_size = module.closest_hit, module.occluded, module.stack_size

    @njit
    def closest(o, d, skip, tri_v, nodes_f, nodes_i, depth):
        sn = np.empty(stack_size(depth), np.int32)
        st = np.empty(stack_size(depth), np.float32)
        hits = 0
        for k in range(o.shape[0]):
            h, _, _, _ = closest_hit(o[k, 0], o[k, 1], o[k, 2], d[k, 0], d[k, 1], d[k, 2], np.inf, skip[k],
                                     tri_v, nodes_f, nodes_i, sn, st)
            hits += h >= 0
        return hits

    @njit
    def anyhit(o, d, skip, tri_v, nodes_f, nodes_i, depth):
        sn = np.empty(stack_size(depth), np.int32)
        st = np.empty(stack_size(depth), np.float32)
        hits = 0
        for k in range(o.shape[0]):
            hits += occluded(o[k, 0], o[k, 1], o[k, 2], d[k, 0], d[k, 1], d[k, 2], np.inf, skip[k],
                             tri_v, nodes_f, nodes_i, sn, st)
        return hits

    return closest, anyhit


def ray_sets(setup, n, seed=1):
    """Primary, bounce and shadow rays from ``n`` random pixels with a first hit (origins and
    directions (5, n, 3): camera origin, camera direction, surface point, bounce and shadow
    directions) and the triangle each secondary ray leaves."""
    rng = np.random.default_rng(seed)
    data = setup.data
    pix = rng.choice(np.flatnonzero(setup.tri >= 0), n)
    tri = setup.tri[pix].astype(np.int64)
    b1, b2 = setup.bary[pix, 0:1], setup.bary[pix, 1:2]
    v = data.tri_v[tri].astype(np.float64).reshape(n, 3, 3)
    p = (1.0 - b1 - b2) * v[:, 0] + b1 * v[:, 1] + b2 * v[:, 2]
    ng = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    ng /= np.linalg.norm(ng, axis=1, keepdims=True)
    ng *= np.where(np.einsum("ij,ij->i", ng, setup.dirs[pix]) > 0.0, -1.0, 1.0)[:, None]
    w = rng.normal(size=(n, 3))
    w = w / np.linalg.norm(w, axis=1, keepdims=True) + ng  # cosine-distributed around ng
    s = rng.normal(size=(n, 3))
    s[:, 1] = np.abs(s[:, 1])
    s = np.where(rng.random((n, 1)) < 0.5, np.asarray(data.lp[0:3])[None, :], s)
    unit = lambda x: x / np.linalg.norm(x, axis=1, keepdims=True)  # noqa: E731
    rays = np.stack([setup.origins[pix], setup.dirs[pix], p + ng * data.eps, unit(w), unit(s)])
    return np.ascontiguousarray(rays), tri


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--scene", default="classroom")
    ap.add_argument("--rays", type=integer(64), default=200000)
    ap.add_argument("--repeats", type=integer(1), default=4)
    ap.add_argument("--baseline", default=None, metavar="REV", help="git revision whose traversal runs too")
    args = ap.parse_args(argv)
    from plugins.renderers.pathtracer import PathTracer, bvh, traverse

    registry = load_plugins()
    scene = harness_scene(registry, args.scene)
    if scene is None:
        print(f"skipping {args.scene!r}: neither a registered scene nor a folder {SCENES / args.scene}")
        return 0
    setup = PathTracer().setup(scene, 0, (1280, 720))
    data = setup.data
    rays, skip = ray_sets(setup, args.rays)
    no_skip = np.full(args.rays, -1, np.int64)
    resident = np.tile(np.arange(64), args.rays // 64)
    c = np.ascontiguousarray
    sets = {"primary": (c(rays[0]), c(rays[1]), no_skip, False), "bounce": (c(rays[2]), c(rays[3]), skip, False),
            "shadow": (c(rays[2]), c(rays[4]), skip, True),
            "resident": (c(rays[2][resident]), c(rays[3][resident]), skip[resident], False)}
    earlier = baseline_package(args.baseline, "plugins/renderers/pathtracer") if args.baseline else nullcontext()
    with earlier as package:
        versions = {"pathtracer": (traverse, bvh)}
        if package is not None:
            versions = {"baseline": tuple(importlib.import_module(f"{package.__name__}.{m}")
                                          for m in ("traverse", "bvh")), **versions}
        verts = data.tri_v.reshape(-1, 3, 3)
        calls = {}
        for name, (trav, tree) in versions.items():
            bounds, child, count, order, depth = tree.build_bvh(verts)
            nodes_f, nodes_i = tree.pack_wide(bounds, child, count)
            closest, anyhit = kernels(trav)
            tri_v = np.ascontiguousarray(verts[order].reshape(-1, 9))
            print(f"{name}: {nodes_f.nbytes / 2**20:.2f} MiB of nodes, {depth} binary levels", flush=True)
            for label, (o, d, s, shadow) in sets.items():
                fn = anyhit if shadow else closest
                tree_args = (tri_v, nodes_f, nodes_i, depth)
                calls[(name, label)] = lambda fn=fn, o=o, d=d, s=s, t=tree_args: fn(o, d, s, *t)
        for (name, label), call in calls.items():  # the warm-up pass: compilation, hit counts
            print(f"{name:<10} {label:<8} hits {call()}")
        result = alternate(calls, args.repeats, warm=False)
    print(f"\n{args.scene}, {args.rays} rays per set, M rays per CPU-second, median [min-max] of {args.repeats}")
    for (name, label), cpu_ms in result.cpu_ms.items():
        v = [len(sets[label][0]) / max(ms, 1e-6) / 1e3 for ms in cpu_ms]
        print(f"{name:<10} {label:<8} {statistics.median(v):6.2f} [{min(v):.2f}-{max(v):.2f}]")
    return 0


if __name__ == "__main__":
    run(main)
