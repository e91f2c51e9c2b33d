"""G-buffer cost of the ``raster`` renderer.

Usage: ``python benchmarks/bench_raster.py [--scene atrium] [--width 1280] [--height 720] [--repeats 5]``

Prints the median, min and max wall-clock milliseconds per frame (``time.perf_counter_ns``) after
one warm-up frame (Numba compilation, GL context), for: the visibility pass plus exact float
attributes (``gbuffer``), a full ``render`` of every G-buffer channel plus the shaded colour, and
the motion channel alone by the renderer's Numba kernel and by its NumPy peer ``Scene.motion``
(same process, same G-buffer).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

from harness import load_plugins  # noqa: E402
from plugins.renderers.raster.motion import motion_vectors  # noqa: E402

GBUFFER = {"albedo", "normal", "depth", "position", "object_id", "motion"}


def timed(fn, repeats: int) -> list[float]:
    fn(0)
    out = []
    for k in range(repeats):
        start = time.perf_counter_ns()
        fn(k % 2)
        out.append((time.perf_counter_ns() - start) / 1e6)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="atrium")
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=720)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    registry = load_plugins()
    scene = registry.get("scene", args.scene).factory()
    renderer = registry.get("renderer", "raster").factory()
    size = (args.width, args.height)
    print(f"scene {args.scene}: {len(scene.triangles(0).vertices)} triangles, {size[0]}x{size[1]}, "
          f"{os.cpu_count()} CPUs")
    rows = {
        "gbuffer (visibility + attributes)": lambda t: renderer.gbuffer(scene, t, *size),
        "render (all G-buffer channels + colour)": lambda t: renderer.render(scene, t, channels=GBUFFER,
                                                                             resolution=size),
    }
    g = renderer.gbuffer(scene, 1, *size)
    rows["motion: Numba kernel (raster)"] = lambda t: motion_vectors(scene, g.position, g.object_id, 1)
    rows["motion: Scene.motion (NumPy peer)"] = lambda t: scene.motion(g.position, g.object_id, 1, *size)
    medians = {}
    for label, fn in rows.items():
        ms = timed(fn, args.repeats)
        medians[label] = statistics.median(ms)
        print(f"{label:42s} median {medians[label]:8.1f} ms  min {min(ms):8.1f}  max {max(ms):8.1f}")
    ratio = medians["motion: Scene.motion (NumPy peer)"] / medians["motion: Numba kernel (raster)"]
    print(f"motion speed-up of the Numba kernel over Scene.motion: {ratio:.1f}x")


if __name__ == "__main__":
    main()
