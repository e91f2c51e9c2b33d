"""G-buffer cost of the ``raster`` renderer.

Usage: ``python benchmarks/bench_raster.py [--scene atrium] [--resolution 1280x720] [--repeats 5]``

Prints wall-clock and process CPU milliseconds per frame, median [min-max] of ``--repeats``
rounds after one warm-up call each (Numba compilation, GL context), the parts taking turns call
by call (:func:`harness.timer.alternate`): the visibility pass plus exact float attributes
(``gbuffer``), a full ``render`` of every G-buffer channel plus the shaded colour, and the motion
channel alone by the renderer's Numba kernel and by its NumPy peer ``Scene.motion`` (same
G-buffer).
"""

from __future__ import annotations

import os

from common import alternate, integer, parser, ratio_line, resolution, run, time_table

from harness import load_plugins
from plugins.renderers.raster.motion import motion_vectors

GBUFFER = {"albedo", "normal", "depth", "position", "object_id", "motion"}


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--scene", default="atrium")
    ap.add_argument("--resolution", type=resolution, default=(1280, 720))
    ap.add_argument("--repeats", type=integer(1), default=5)
    args = ap.parse_args(argv)
    registry = load_plugins()
    scene = registry.get("scene", args.scene).factory()
    renderer = registry.get("renderer", "raster").factory()
    size = args.resolution
    print(f"scene {args.scene}: {len(scene.triangles(0).vertices)} triangles, {size[0]}x{size[1]}, "
          f"{os.cpu_count()} CPUs")
    g = renderer.gbuffer(scene, 1, *size)
    calls = {
        "gbuffer": lambda: renderer.gbuffer(scene, 1, *size),
        "render": lambda: renderer.render(scene, 1, channels=GBUFFER, resolution=size),
        "motion (Numba)": lambda: motion_vectors(scene, g.position, g.object_id, 1),
        "motion (NumPy)": lambda: scene.motion(g.position, g.object_id, 1, *size),
    }
    result = alternate(calls, args.repeats)
    print(time_table(result))
    print(ratio_line(result, "motion (NumPy)", "motion (Numba)"))
    return 0


if __name__ == "__main__":
    run(main)
