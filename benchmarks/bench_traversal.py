"""Ray queries of the ``pathtracer`` alone: closest hit and any hit on rays of a real scene.

Usage::

    NUMBA_NUM_THREADS=1 python benchmarks/bench_traversal.py [--scene classroom] [--rays 200000]
                                                             [--repeats 4] [--baseline FOLDER]

Three ray sets from the first hits of the scene's camera at 1280x720 (pixels drawn at random):
``primary`` (the camera rays), ``bounce`` (from the first hit, offset as the integrator does, in a
cosine-distributed direction around the geometric normal turned to the camera) and ``shadow``
(any-hit queries from the same points, half towards the sun, half in random directions of the
upper hemisphere, unbounded). Each set is traced in a single-threaded loop; the figure is rays
per CPU-second (median and range of ``--repeats`` passes after one warm-up pass). Also printed:
the same bounce rays when only 64 distinct rays are repeated (``resident``, the tree's paths then
stay in cache), which bounds what memory latency costs.

``--baseline FOLDER``: the traversal and BVH of an earlier copy of the project (``git archive REV
| tar -x -C FOLDER``) on the same rays, alternating with ours pass by pass; the hit counts of the
two must agree.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
from bench_pathtracer import SCENES, _import_copy, harness_scene
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="classroom")
    parser.add_argument("--rays", type=int, default=200000)
    parser.add_argument("--repeats", type=int, default=4)
    parser.add_argument("--baseline", type=Path, default=None, help="folder with a copy of an earlier pathtracer")
    args = parser.parse_args()
    from plugins.renderers.pathtracer import PathTracer, bvh, traverse

    registry = load_plugins()
    scene = harness_scene(registry, args.scene)
    if scene is None:
        print(f"skipping {args.scene!r}: neither a registered scene nor a folder {SCENES / args.scene}")
        return
    setup = PathTracer().setup(scene, 0, (1280, 720))
    data = setup.data
    rays, skip = ray_sets(setup, args.rays)
    no_skip = np.full(args.rays, -1, np.int64)
    resident = np.tile(np.arange(64), args.rays // 64)
    c = np.ascontiguousarray
    sets = {"primary": (c(rays[0]), c(rays[1]), no_skip, False), "bounce": (c(rays[2]), c(rays[3]), skip, False),
            "shadow": (c(rays[2]), c(rays[4]), skip, True),
            "resident": (c(rays[2][resident]), c(rays[3][resident]), skip[resident], False)}
    versions = {"pathtracer": (traverse, bvh)}
    if args.baseline is not None:
        old = _import_copy(args.baseline.resolve() / "plugins" / "renderers" / "pathtracer", "baseline_pathtracer")
        import baseline_pathtracer.bvh as old_bvh
        import baseline_pathtracer.traverse as old_traverse

        versions = {"baseline": (old_traverse, old_bvh), **versions}
        del old
    verts = data.tri_v.reshape(-1, 3, 3)
    prepared = {}
    for name, (trav, tree) in versions.items():
        bounds, child, count, order, depth = tree.build_bvh(verts)
        nodes_f, nodes_i = tree.pack_wide(bounds, child, count)
        prepared[name] = (kernels(trav), np.ascontiguousarray(verts[order].reshape(-1, 9)), nodes_f, nodes_i, depth)
        print(f"{name}: {nodes_f.nbytes / 2**20:.2f} MiB of nodes, {depth} binary levels", flush=True)
    rates = {}
    for rep in range(args.repeats + 1):
        for name, ((closest, anyhit), tri_v, nodes_f, nodes_i, depth) in prepared.items():
            for label, (o, d, s, shadow) in sets.items():
                fn = anyhit if shadow else closest
                c0 = time.process_time()
                hits = fn(o, d, s, tri_v, nodes_f, nodes_i, depth)
                dt = time.process_time() - c0
                if rep == 0:
                    print(f"{name:<10} {label:<8} hits {hits}")
                else:
                    rates.setdefault((name, label), []).append(len(o) / max(dt, 1e-9) / 1e6)
    print(f"\n{args.scene}, {args.rays} rays per set, M rays per CPU-second, median [min-max] of {args.repeats}")
    for (name, label), v in rates.items():
        print(f"{name:<10} {label:<8} {statistics.median(v):6.2f} [{min(v):.2f}-{max(v):.2f}]")


if __name__ == "__main__":
    main()
