"""The ``eaw`` filter's per-frame preparation (``layout.survey`` and ``layout.pack``) against a
git revision's, in one process, alternating.

One ``synthetic-moving`` frame (the channels ``eaw`` reads: colour, normal, position) is
surveyed and packed by the current :mod:`plugins.filters.eaw.layout` and by the one at git
revision ``--baseline`` (the whole ``eaw`` package of that revision, extracted to a temporary
folder and imported from there: :mod:`harness.bench_baseline`), the passes taking turns call by
call (:func:`harness.timer.alternate`), each timed in process CPU time (all threads together)
and wall-clock time; also ``layout.unpack`` (the CUDA
backend's last step, on the host). Before timing, the script checks that both give the same
pixel classes, row sums, planes, runs and unpacked frame, and prints the largest difference of
the colour scale. The memory floor of the filter (:class:`harness.floor.Floor`: read colour,
normal, position, write one frame) is timed in the same rounds. The whole filter against a
revision is ``denoise-bench bench eaw --rounds N --baseline REV``.

Usage::

    NUMBA_NUM_THREADS=1 python benchmarks/bench_eaw_prepare.py --threads 1 --rounds 21
    NUMBA_NUM_THREADS=2 python benchmarks/bench_eaw_prepare.py --threads 1,2 --rounds 21
"""

from __future__ import annotations

import importlib

import numpy as np
from common import (
    alternate,
    baseline_package,
    integer,
    parser,
    ratio_line,
    resolution,
    run,
    thread_counts,
    time_table,
    using_threads,
)
from numba import get_num_threads

from harness import load_plugins
from harness.floor import Floor
from plugins.filters.eaw import layout
from plugins.filters.eaw.params import EAWParams


class Preparer:
    """Survey and pack of one ``layout`` module on one frame, with buffers of its own."""

    def __init__(self, module, frame, params):
        self.m = module
        self.color, self.normal, self.position = (np.ascontiguousarray(frame[k], np.float32)
                                                  for k in ("color", "normal", "position"))
        self.params = params
        self.b = module.Buffers(frame.height, frame.width, params.halo())
        self.scales = None
        self.out = np.empty_like(self.color)

    def survey(self):
        b, m = self.b, self.m
        m.survey(self.color, self.normal, self.position, m._NO_IDS, m._NO_DEPTH, m._NO_VARIANCE, False, False,
                 False, b.state, b.row_log, b.row_count, b.row_lo, b.row_hi)

    def scale(self):
        b = self.b
        self.scales = self.m.frame_scales(b.row_log, b.row_count, b.row_lo, b.row_hi, self.params.color_scale,
                                          self.params.position_units)

    def pack(self):
        b = self.b
        scale, origin, pos_unit = self.scales
        self.m.pack(self.color, self.normal, self.position, b.state, 1.0 / scale, origin, 1.0 / pos_unit, b.halo,
                    b.stride, b.color[0], b.color[1], b.guide, b.runs, b.run_count, b.row_surface)

    def unpack(self):
        """The CUDA backend's last step (here on the packed colour itself)."""
        b, scale = self.b, self.scales[0]
        self.m.unpack(self.color, b.state, b.color[1], 1.0 / scale, scale, b.halo, b.stride, self.out)


def compare(old: Preparer, new: Preparer) -> None:
    """Print how the two preparations differ (the buffers are compared bit for bit)."""
    a, b = old.b, new.b
    print(f"colour scale: {old.scales[0]!r} (baseline) {new.scales[0]!r} (now), relative difference "
          f"{abs(new.scales[0] / old.scales[0] - 1.0):.1e}")
    same = {name: np.array_equal(getattr(a, name), getattr(b, name))
            for name in ("state", "row_count", "row_lo", "row_hi", "run_count", "row_surface")}
    same["row_log"] = np.array_equal(a.row_log, b.row_log)
    same["runs"] = all(np.array_equal(a.runs[y, :a.run_count[y]], b.runs[y, :b.run_count[y]])
                       for y in range(a.height))
    for name in ("color", "guide"):
        one = getattr(a, name) if name == "guide" else np.concatenate(getattr(a, name))
        two = getattr(b, name) if name == "guide" else np.concatenate(getattr(b, name))
        same[name] = np.array_equal(one.view(np.uint32), two.view(np.uint32))
    print("bit-identical: " + ", ".join(f"{k} {'yes' if v else 'NO'}" for k, v in same.items()))
    if not same["row_log"]:
        rel = np.abs(b.row_log - a.row_log) / np.maximum(np.abs(a.row_log), 1e-300)
        print(f"  row_log: largest relative difference {rel.max():.1e}")


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--resolution", type=resolution, default=(1280, 720))
    ap.add_argument("--threads", type=thread_counts, default=None, help="comma-separated thread counts (default: all)")
    ap.add_argument("--rounds", type=integer(1), default=21)
    ap.add_argument("--scene", default="synthetic-moving")
    ap.add_argument("--baseline", default="main", help="git revision whose layout is timed too")
    args = ap.parse_args(argv)
    w, h = args.resolution
    reg = load_plugins()
    frame = reg.renderers["synthetic"].factory().render(
        reg.scenes[args.scene].factory(), 1, spp=1, seed=0, channels=frozenset({"color", "normal", "position"}),
        resolution=(w, h))
    params = EAWParams()
    with baseline_package(args.baseline, "plugins/filters/eaw") as package:
        old = Preparer(importlib.import_module(package.__name__ + ".layout"), frame, params)
        new = Preparer(layout, frame, params)
        for p in (old, new):  # compile, warm up
            p.survey()
            p.scale()
            p.pack()
            p.unpack()
        compare(old, new)
        same = np.array_equal(old.out.view(np.uint32), new.out.view(np.uint32))
        print(f"unpack: bit-identical {'yes' if same else 'NO'}")
        active = np.mean(new.b.state == layout.ACTIVE)
        floor = Floor({"normal", "position"})
        passes = {"survey@base": old.survey, "survey": new.survey, "pack@base": old.pack, "pack": new.pack,
                  "unpack@base": old.unpack, "unpack": new.unpack, "floor": lambda: floor(frame)}
        for n in args.threads or [get_num_threads()]:
            with using_threads(n):
                result = alternate(passes, args.rounds)
            print(f"\n{w}x{h}, {args.scene} (active {active:.1%}), {n} thread(s), {args.rounds} rounds, "
                  f"baseline {args.baseline}; ms per pass")
            print(time_table(result, width=12, digits=2))
            for stage in ("survey", "pack", "unpack"):
                for clock in ("wall", "cpu"):
                    print("  " + ratio_line(result, f"{stage}@base", stage, clock))
            for clock in ("wall", "cpu"):
                times = result.ms if clock == "wall" else result.cpu_ms
                both = np.add(times["survey"], times["pack"])
                ratio = np.add(times["survey@base"], times["pack@base"]) / both
                print(f"  survey + pack ({clock}): now median {np.median(both):.2f} ms, before / now per round "
                      f"median {np.median(ratio):.2f}, range {ratio.min():.2f}-{ratio.max():.2f}")
    return 0


if __name__ == "__main__":
    run(main)
