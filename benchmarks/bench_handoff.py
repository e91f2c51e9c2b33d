"""What the ``local`` executor's worker process costs, against running jobs in this process.

Prints, for one group of frames at the given resolution:

* the worker's start-up time (interpreter, plugins);
* the wall time of a trivial job (``passthrough``, one timed call per frame) run inline and in
  the worker: the difference is the per-job hand-off (task out, rows back); the first job of a
  group also carries the group's frames to the worker;
* a real filter's per-frame median time measured inline and in the worker, alternating, to show
  that the worker adds nothing inside the timed region.

Usage::

    python benchmarks/bench_handoff.py --resolution 1280x720 --frames 4 --jobs 10 --filter eaw --rounds 3

The figures measured with that command, the machine and their reading are in
docs/architecture.md ("The worker hand-off").
"""

from __future__ import annotations

import statistics

from common import integer, parser, run, timed_call
from common import resolution as size_type

from harness import load_plugins
from harness.cache import Cache, make_key
from harness.executors import InlineExecutor, LocalExecutor
from harness.executors.base import PluginOptions, Shared
from harness.jobs import GroupInputs
from harness.machine import cpu_model
from harness.plan import Job, MetricPlan
from harness.renders import RenderStore
from harness.units import JobUnit


def group_inputs(reg, resolution, frames, channels) -> GroupInputs:
    store = RenderStore(reg, Cache(enabled=False), resolution=resolution)
    inputs = GroupInputs([], [], [], [], channels=channels)
    for t in range(frames):
        inputs.frames.append(store.frame("synthetic-moving", "synthetic", t, spp=1, seed=0, channels=channels))
        inputs.references.append(store.reference("synthetic-moving", "synthetic", t, spp=0))
        inputs.reference_hashes.append("")
        inputs.repaired.append(0)
    return inputs


def tasks_for(name, resolution, frames, repeats, inputs, count, key):
    job = Job("denoise", "synthetic-moving", "synthetic", name, "cpu", "{}", "", 1, 0, width=resolution[0],
              height=resolution[1], frames=frames, repeats=repeats)
    return [JobUnit(job, MetricPlan(), Shared(key, inputs)) for _ in range(count)]


def timed_run(executor, tasks):
    """(wall seconds, outcomes) of running ``tasks``; every one must succeed."""
    outcomes, ms, _ = timed_call(lambda: [o for _, o in executor.run(tasks)])
    if not all(o.ok for o in outcomes):
        raise RuntimeError(f"a task failed: {[o.error for o in outcomes if not o.ok]}")
    return ms / 1e3, outcomes


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--resolution", type=size_type, default=(1280, 720))
    ap.add_argument("--frames", type=integer(1), default=4)
    ap.add_argument("--jobs", type=integer(1), default=10)
    ap.add_argument("--filter", default="eaw")
    ap.add_argument("--rounds", type=integer(1), default=3)
    args = ap.parse_args(argv)
    resolution = args.resolution
    reg = load_plugins()
    channels = frozenset(reg.filters[args.filter].requires | {"normal", "position"})
    inputs = group_inputs(reg, resolution, args.frames, channels)
    megabytes = sum(a.nbytes for f in inputs.frames for a in f.arrays().values()) / 1e6
    megabytes += sum(r.nbytes for r in inputs.references) / 1e6
    print(f"{cpu_model()}; {resolution[0]}x{resolution[1]}, {args.frames} frames, {megabytes:.0f} MB of inputs "
          "per group")

    inline = InlineExecutor(reg)
    local = LocalExecutor(plugins=PluginOptions(), timeout=600)
    print(f"worker start-up: {timed_call(local._start)[1] / 1e3:.2f} s")

    trivial = []
    for r in range(args.rounds):
        key = make_key(round=r)
        for name, ex in (("inline", inline), ("local", local)):
            first, _ = timed_run(ex, tasks_for("passthrough", resolution, args.frames, 1, inputs, 1, key))
            rest, _ = timed_run(ex, tasks_for("passthrough", resolution, args.frames, 1, inputs, args.jobs, key))
            trivial.append((name, first, rest / args.jobs))
    for name in ("inline", "local"):
        firsts = [f for n, f, _ in trivial if n == name]
        per = [p for n, _, p in trivial if n == name]
        print(f"passthrough job, {name:6s}: first of a group {1e3 * statistics.median(firsts):7.1f} ms, "
              f"then {1e3 * statistics.median(per):7.1f} ms per job (median of {args.rounds} rounds)")
    hand = statistics.median(p for n, _, p in trivial if n == "local") - statistics.median(
        p for n, _, p in trivial if n == "inline")
    ship = statistics.median(f for n, f, _ in trivial if n == "local") - statistics.median(
        f for n, f, _ in trivial if n == "inline")
    print(f"hand-off per job: {1e3 * hand:.1f} ms; shipping a group's inputs once: {1e3 * (ship - hand):.1f} ms")

    ms = {"inline": [], "local": []}
    for r in range(args.rounds):
        key = make_key(timing=r)
        for name, ex in (("inline", inline), ("local", local)):
            _, outcomes = timed_run(ex, tasks_for(args.filter, resolution, 2, 5, inputs, 1, key))
            ms[name].append(outcomes[0].value.rows[-1].ms_median)
    for name, values in ms.items():
        print(f"{args.filter} ms per frame, {name:6s}: " + ", ".join(f"{v:.1f}" for v in values))
    local.close()
    return 0


if __name__ == "__main__":
    run(main)
