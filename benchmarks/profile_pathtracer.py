"""Where a path-tracer frame spends its time, by switches of the production kernels.

Usage::

    NUMBA_NUM_THREADS=1 python benchmarks/profile_pathtracer.py [--scene classroom] [--width 1280]
                                                               [--height 720] [--repeats 3]

Renders one scene (``../shared/scenes/<scene>`` through the Mitsuba loader, or a registered
scene) at 1 spp and times, in one process and taking turns call by call
(:func:`harness.timer.alternate`), the parts a frame is made of (process CPU time, median of
``--repeats`` after one untimed call each):

- ``setup``: the primary rays and first hits (:func:`.integrator.first_hits`), once per frame;
- ``paths D`` for ``max_depth`` D = 1 .. ``--max-depth``: the path kernel alone, from the same
  first hits. D = 1 is the per-path cost without any ray (random-number stream, the first hit's
  surface, emission); each step D - 1 -> D adds one vertex: its light sample, BSDF evaluation and
  shadow ray, its BSDF sample and the segment to the next vertex;
- ``paths D, bsdf``: the deepest ``max_depth`` without next-event estimation (``strategy="bsdf"``):
  the difference to ``paths D`` is what light sampling, the BSDF evaluations and the shadow rays
  cost.

Prints microseconds per pixel for each part and the increments. Then next-event estimation's
light sample alone (:func:`.lights.sample_light`, single-threaded, from each first hit of the
frame, one call per hit): nanoseconds per call over the random numbers and the hit's surface that
it needs, with the scene's light choice, with every sample from the sun, with every sample from
the environment, and the scene's sample followed by its shadow ray (the any-hit query of the
integrator, without the BSDF evaluation). Traversal alone, per ray, is
``benchmarks/bench_traversal.py``.
"""

from __future__ import annotations

import statistics
import warnings

import numpy as np
from bench_pathtracer import SCENES, harness_scene
from common import alternate, integer, parser, run

from harness import load_plugins

SURFACE, SAMPLE, SHADOW = 0, 1, 2


def light_kernel():
    """A single-threaded loop over a frame's first hits: random numbers and surface, plus the light
    sample, plus its shadow ray (``mode``); returns a checksum and the count of occluded samples."""
    from numba import njit

    from plugins.renderers.pathtracer.integrator import surface
    from plugins.renderers.pathtracer.lights import sample_light
    from plugins.renderers.pathtracer.rng import stream_key, uniform
    from plugins.renderers.pathtracer.traverse import occluded, stack_size

    @njit(error_model="numpy")
    def kernel(mode, tri, bary, geom, mats, lights, lp, eps, depth):
        tri_v, tri_n, tri_uv, tri_mat, nodes_f, nodes_i, tri_front = geom
        mat_flags, mat_emit = mats[1], mats[2]
        emit_tri, emit_cdf, tri_light_pdf, env_img, cdf_rows, cdf_cols = lights
        stack_n = np.empty(stack_size(depth), np.int32)
        stack_t = np.empty(stack_size(depth), np.float32)
        total = 0.0
        blocked = 0
        for i in range(tri.shape[0]):
            if tri[i] < 0:
                continue
            p, ng, _ns, _u, _v = surface(tri[i], bary[i, 0], bary[i, 1], tri_v, tri_n, tri_uv)
            key = stream_key(1, 0, i, 0)
            u0, u1, u2 = uniform(key, 0), uniform(key, 1), uniform(key, 2)
            if mode == SURFACE:
                total += u0 + u1 + u2 + p[0] + ng[0]
                continue
            ld, _dist, le, pdf, _t = sample_light(u0, u1, u2, p, lp, tri_v, tri_mat, mat_emit, mat_flags, tri_front,
                                                  emit_tri, emit_cdf, tri_light_pdf, env_img, cdf_rows, cdf_cols)
            total += pdf + le[0] + ld[0]
            if mode == SHADOW and pdf > 0.0:
                off = eps if ld[0] * ng[0] + ld[1] * ng[1] + ld[2] * ng[2] > 0.0 else -eps
                if occluded(p[0] + ng[0] * off, p[1] + ng[1] * off, p[2] + ng[2] * off, ld[0], ld[1], ld[2], np.inf,
                            tri[i], tri_v, nodes_f, nodes_i, stack_n, stack_t):
                    blocked += 1
        return total, blocked

    return kernel


def light_sampling(setup, repeats: int) -> None:
    """Nanoseconds per light sample (and shadow ray) at the first hits of ``setup``'s frame."""
    import plugins.renderers.pathtracer.lights as L

    data = setup.data
    kernel = light_kernel()
    hits = int((setup.tri >= 0).sum())
    if hits == 0:
        return
    lp_sun, lp_env = data.lp.copy(), data.lp.copy()
    infinite = data.lp[L.P_SUN] + data.lp[L.P_ENV]
    lp_sun[L.P_SUN], lp_sun[L.P_ENV] = infinite, 0.0
    lp_env[L.P_SUN], lp_env[L.P_ENV] = 0.0, infinite

    def part(mode, lp):
        args = (setup.tri, setup.bary, data.geometry(), data.materials(), data.lights(), lp, data.eps, data.depth)
        return lambda: kernel(mode, *args)

    parts = {"surface": part(SURFACE, data.lp), "light sample": part(SAMPLE, data.lp)}
    if data.lp[L.P_SUN] > 0.0 and data.lp[L.P_ENV] > 0.0:
        parts["  all from sun"] = part(SAMPLE, lp_sun)
        parts["  all from env"] = part(SAMPLE, lp_env)
    parts["+ shadow ray"] = part(SHADOW, data.lp)
    ns = {name: statistics.median(v) * 1e6 / hits for name, v in alternate(parts, repeats).cpu_ms.items()}
    _, blocked = parts["+ shadow ray"]()
    print(f"\nlight samples at the {hits} first hits (P_tri {data.lp[L.P_TRI]:.2f}, P_sun {data.lp[L.P_SUN]:.2f}, "
          f"P_env {data.lp[L.P_ENV]:.2f}; {blocked / hits:.0%} occluded); CPU nanoseconds per hit, median of {repeats}")
    for name, v in ns.items():
        over = ns["light sample"] if name == "+ shadow ray" else ns["surface"]
        print(f"{name:<16} {v:7.1f}" + ("" if name == "surface" else f"  +{v - over:.1f}"))


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--scene", default="classroom")
    ap.add_argument("--width", type=integer(1), default=1280)
    ap.add_argument("--height", type=integer(1), default=720)
    ap.add_argument("--max-depth", type=integer(1), default=5)
    ap.add_argument("--repeats", type=integer(1), default=3)
    args = ap.parse_args(argv)
    from plugins.renderers.pathtracer import PathTracer
    from plugins.renderers.pathtracer.pixels import PixelState

    registry = load_plugins()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = harness_scene(registry, args.scene)
    if scene is None:
        print(f"skipping {args.scene!r}: neither a registered scene nor a folder {SCENES / args.scene}")
        return 0
    size = (args.width, args.height)
    n = args.width * args.height
    base = PathTracer(max_depth=args.max_depth)
    setup = base.setup(scene, 0, size)

    def first_hits():
        base._setups.clear()
        base.setup(scene, 0, size)

    def paths(renderer):
        def run():
            state = PixelState(n)
            renderer.add_samples(setup, state, np.ones(n, np.int64), 0, moments=False, split=False)
        return run

    parts = {"setup": first_hits}
    for depth in range(1, args.max_depth + 1):
        parts[f"paths {depth}"] = paths(PathTracer(max_depth=depth))
    parts[f"paths {args.max_depth}, bsdf"] = paths(PathTracer(max_depth=args.max_depth, strategy="bsdf"))
    cpu = {name: [ms / 1e3 for ms in v] for name, v in alternate(parts, args.repeats).cpu_ms.items()}
    us = {name: statistics.median(v) / n * 1e6 for name, v in cpu.items()}
    print(f"\n{args.scene} {args.width}x{args.height}, 1 spp; CPU microseconds per pixel, median of {args.repeats} "
          f"[min-max]")
    previous = None
    for name, v in cpu.items():
        spread = f"[{min(v) / n * 1e6:.3f}-{max(v) / n * 1e6:.3f}]"
        step = ""
        if name.startswith("paths") and "bsdf" not in name:
            step = f"  +{us[name] - us[previous]:.3f} over {previous}" if previous else ""
            previous = name
        print(f"{name:<16} {us[name]:7.3f} {spread:>18}{step}")
    deepest = f"paths {args.max_depth}"
    total = us["setup"] + us[deepest]
    print(f"frame (setup + {deepest}) {total:.3f}; setup {us['setup'] / total:.0%}, per-path fixed cost "
          f"{us['paths 1'] / total:.0%}, next-event estimation {(us[deepest] - us[deepest + ', bsdf']) / total:.0%}")
    light_sampling(setup, args.repeats)
    return 0


if __name__ == "__main__":
    run(main)
