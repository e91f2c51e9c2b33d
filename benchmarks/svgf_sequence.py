"""Steady-state per-frame time of ``svgf`` over a sequence, with its stages, against ``eaw``.

``denoise-bench bench`` times the second frame of a sequence, where SVGF's history is still
short (spatial variance everywhere). This script times the frames after the first ``--warm``
ones, where the temporal variance is used, and prints the median of each stage.

Usage::

    python benchmarks/svgf_sequence.py --resolution 1280x720 --frames 10 --warm 5
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from harness import CHANNELS, load_plugins


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", default="1280x720")
    parser.add_argument("--frames", type=int, default=10)
    parser.add_argument("--warm", type=int, default=5, help="frames run before timing")
    parser.add_argument("--scene", default="synthetic-moving")
    parser.add_argument("--peers", default="eaw")
    args = parser.parse_args()
    width, height = (int(v) for v in args.resolution.split("x"))
    reg = load_plugins()
    renderer = reg.renderers["synthetic"].factory()
    scene = reg.scenes[args.scene].factory()
    frames = [renderer.render(scene, k, spp=1, seed=0, channels=frozenset(CHANNELS), resolution=(width, height))
              for k in range(args.frames)]
    filters = {}
    for name in ["svgf", *[p for p in args.peers.split(",") if p]]:
        if name not in reg.filters:
            print(f"{name}: not registered, skipped")
            continue
        variants = ((name, {}),) if name != "svgf" else (
            ("svgf (direct+indirect)", {}), ("svgf (colour)", {"separate_lighting": False}))
        for label, params in variants:
            filters[label] = reg.filters[name].factory(backend="cpu", **params)
    # the filters take turns on each frame, so that a change in the machine's load hits all
    times = {label: [] for label in filters}
    stages = {label: [] for label in filters}
    for k, frame in enumerate(frames):
        for label, filt in filters.items():
            start = time.perf_counter()
            filt(frame)
            elapsed = (time.perf_counter() - start) * 1e3
            if k >= args.warm:
                times[label].append(elapsed)
                stages[label].append(dict(getattr(filt, "stage_ms", {})))
    results = {}
    for label in filters:
        results[label] = float(np.median(times[label]))
        stage_text = ", ".join(f"{key} {np.median([s[key] for s in stages[label]]):.1f}" for key in stages[label][0])
        print(f"{label}: median {results[label]:.1f} ms, min {min(times[label]):.1f}, max {max(times[label]):.1f}"
              + (f"\n    stages (median ms): {stage_text}" if stage_text else ""))
    for label, ms in results.items():
        if label.startswith("svgf") and "eaw" in results:
            print(f"{label} / eaw = {ms / results['eaw']:.2f}")


if __name__ == "__main__":
    main()
