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

Prints microseconds per pixel for each part and the increments. Traversal alone, per ray, is
``benchmarks/bench_traversal.py``.
"""

from __future__ import annotations

import statistics
import warnings

import numpy as np
from bench_pathtracer import SCENES, harness_scene
from common import alternate, integer, parser, run

from harness import load_plugins


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
    return 0


if __name__ == "__main__":
    run(main)
