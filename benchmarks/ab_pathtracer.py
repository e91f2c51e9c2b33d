"""CPU time per frame of the path tracer against an earlier copy of the project, frames alternating.

    git archive REV | tar -x -C /tmp/before
    NUMBA_NUM_THREADS=1 python benchmarks/ab_pathtracer.py --baseline /tmp/before \\
        [--scene classroom --width 640 --height 360 --repeats 10]

Both versions load ``../shared/scenes/<scene>`` with their own Mitsuba loader and render it at 1
spp, ``max_depth`` 5, ``rr_depth`` 5 (scene data built once, before timing; one untimed frame
each to compile), then take turns frame by frame (the order swapped every pair). Prints each
version's process CPU time per frame (min, median, max) and the ratio this / baseline per frame
pair. With one Numba thread this isolates the path kernel from thread scheduling on a shared machine.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench_pathtracer import baseline  # noqa: E402

from plugins.renderers.pathtracer import PathTracer  # noqa: E402
from plugins.scenes.mitsuba import load  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", type=Path, required=True, help="folder with a copy of an earlier project")
    parser.add_argument("--scene", default="classroom")
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=360)
    parser.add_argument("--repeats", type=int, default=10)
    args = parser.parse_args()
    old_tracer, old_load = baseline(args.baseline.resolve())
    warnings.simplefilter("ignore")
    folder = Path(__file__).resolve().parent.parent.parent / "shared" / "scenes" / args.scene
    size = (args.width, args.height)
    runs = {"this": (PathTracer(max_depth=5, rr_depth=5), load(folder)),
            "baseline": (old_tracer(max_depth=5, rr_depth=5), old_load(folder))}
    for renderer, scene in runs.values():
        renderer.render(scene, 0, spp=1, seed=0, resolution=size)
    times: dict[str, list[float]] = {name: [] for name in runs}
    for k in range(args.repeats):
        for name in (("this", "baseline") if k % 2 == 0 else ("baseline", "this")):
            renderer, scene = runs[name]
            start = time.process_time()
            renderer.render(scene, 0, spp=1, seed=k + 1, resolution=size)
            times[name].append(time.process_time() - start)
    for name, values in times.items():
        ms = np.asarray(values) * 1e3
        print(f"{name:9s} {args.scene} {args.width}x{args.height}: CPU ms per frame min {ms.min():.0f} "
              f"median {np.median(ms):.0f} max {ms.max():.0f}")
    ratio = np.asarray(times["this"]) / np.asarray(times["baseline"])
    print(f"this / baseline CPU time per frame pair: median {np.median(ratio):.3f} "
          f"(range {ratio.min():.3f}-{ratio.max():.3f}); min / min {min(times['this']) / min(times['baseline']):.3f}")


if __name__ == "__main__":
    main()
