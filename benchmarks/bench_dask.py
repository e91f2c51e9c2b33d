"""Reference throughput on a Dask cluster against rendering in this process, and the per-task overhead.

For one scene and resolution it renders the same chunked reference (path tracer, ``accumulate``)
three ways, alternating, ``--rounds`` times:

* ``local``: in this process (:meth:`RenderStore.reference`), every Numba thread;
* ``dask-1``: a ``LocalCluster`` of 1 worker process (every Numba thread), one task per chunk;
* ``dask-2``: a ``LocalCluster`` of 2 worker processes (their share of the cores each).

and prints paths per second (wall) for each, the scaling efficiency of ``dask-2`` (its rate over
the ``local`` rate times the cores it uses, against the cores ``local`` uses: both use every
core, so it is the rate ratio), and paths per CPU-second summed over the client and the workers
(robust to other load on the machine). Every reference is checked bit for bit against the local
one.

The per-task overhead is measured on ``dask-1`` as the extra wall time per task over the local
render of the same samples with small chunks (many tasks), and, separately, as the round trip
of a task that renders one sample of a 1x1 image. From the overhead ``o`` and the per-worker
rate ``r`` the chunk size at which the overhead is under 5% at ``W x H`` is
``c = 20 * o * r / (W * H)`` samples; and the projected wall time of a reference of ``--project``
on ``N`` cores is ``paths / (N * rate per core * efficiency) + overhead * tasks / workers``.

Usage::

    python benchmarks/bench_dask.py --scene cornell --resolution 128x128 --spp 128 --chunk 16 --rounds 3

Figures, machine and reading: docs/cluster.md ("Throughput and overhead").
"""

from __future__ import annotations

import math
import os
import statistics
import time

import numpy as np
from common import integer, parser, resolution, run, timed_call


def render(store, renders, scene, spp, chunk, client=None):
    """(wall s, CPU s of client and workers, reference) of one reference, here or on a cluster.

    The wall and the client's CPU time are :func:`harness.timer.timed_call`'s; the workers' CPU
    time is each worker process's ``time.process_time`` before and after.
    """
    workers_before = sum(client.run(time.process_time).values()) if client is not None else 0.0
    if renders is None:
        ref, wall_ms, cpu_ms = timed_call(lambda: store.reference(scene, "pathtracer", 0, spp=spp, chunk=chunk))
    else:
        ref, wall_ms, cpu_ms = timed_call(lambda: renders.reference(scene, "pathtracer", 0, spp=spp).result())
    cpu = cpu_ms / 1e3
    if client is not None:
        cpu += sum(client.run(time.process_time).values()) - workers_before
    return wall_ms / 1e3, cpu, ref


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--scene", default="cornell")
    ap.add_argument("--resolution", type=resolution, default=(128, 128))
    ap.add_argument("--spp", type=integer(1), default=128)
    ap.add_argument("--chunk", type=integer(1), default=16, help="samples per task in the throughput runs")
    ap.add_argument("--small-chunk", type=integer(1), default=2, help="samples per task in the overhead run")
    ap.add_argument("--rounds", type=integer(1), default=3)
    ap.add_argument("--project", type=resolution, default=(1280, 720), metavar="WxH")
    ap.add_argument("--project-spp", type=integer(1), default=4096)
    args = ap.parse_args(argv)

    import numba

    from harness import load_plugins
    from harness.cache import Cache
    from harness.executors import make_executor
    from harness.machine import cpu_model
    from harness.remote_renders import RemoteRenders
    from harness.renders import RenderStore

    reg = load_plugins()
    cores = len(os.sched_getaffinity(0))
    pixels = args.resolution[0] * args.resolution[1]
    paths = pixels * args.spp

    def fresh_store():
        return RenderStore(reg, Cache(enabled=False), resolution=args.resolution)

    base = fresh_store()
    scene = base.scene(args.scene)
    expected = base.reference(scene, "pathtracer", 0, spp=args.spp, chunk=args.chunk)  # compiles, warms up
    print(f"{cpu_model()}, {cores} cores, {numba.get_num_threads()} Numba threads; load average "
          f"{os.getloadavg()[0]:.1f}; {args.scene} {args.resolution[0]}x{args.resolution[1]}, {args.spp} spp "
          f"({paths / 1e6:.2f} M paths), {args.chunk} spp per task")

    clusters = {n: make_executor("dask", registry=reg, workers=n, dashboard_address=":0") for n in (1, 2)}
    try:
        for executor in clusters.values():  # load plugins and kernels in every worker
            with RemoteRenders(fresh_store(), executor, chunk=1) as renders:
                renders.reference(scene, "pathtracer", 0, spp=len(executor.workers())).result()
        results: dict[str, list] = {"local": [], "dask-1": [], "dask-2": []}
        for _ in range(args.rounds):
            results["local"].append(render(fresh_store(), None, scene, args.spp, args.chunk))
            for n, executor in clusters.items():
                with RemoteRenders(fresh_store(), executor, chunk=args.chunk) as renders:
                    results[f"dask-{n}"].append(render(None, renders, scene, args.spp, args.chunk,
                                                       executor.client))
        for name, runs in results.items():
            assert all(np.array_equal(ref, expected) for _, _, ref in runs), f"{name}: not bit-identical"
        rate = {name: [paths / wall for wall, _, _ in runs] for name, runs in results.items()}
        per_cpu = {name: [paths / cpu for _, cpu, _ in runs] for name, runs in results.items()}
        print("\nconfiguration   M paths/s (wall, median [min-max])   M paths per CPU-second (median)")
        for name in results:
            r = rate[name]
            print(f"{name:<15} {statistics.median(r) / 1e6:6.3f} [{min(r) / 1e6:.3f}-{max(r) / 1e6:.3f}]"
                  f"{'':20}{statistics.median(per_cpu[name]) / 1e6:6.3f}")
        ratio = [d / loc for d, loc in zip(rate["dask-2"], rate["local"])]
        print(f"\nscaling efficiency of dask-2 (rate / local rate, both on all {cores} cores): median "
              f"{statistics.median(ratio):.3f} [{min(ratio):.3f}-{max(ratio):.3f}]")
        ratio1 = [d / loc for d, loc in zip(rate["dask-1"], rate["local"])]
        print(f"dask-1 rate / local rate: median {statistics.median(ratio1):.3f} [{min(ratio1):.3f}-{max(ratio1):.3f}]")

        # ---------------------------------------------------------------- per-task overhead
        one = clusters[1]
        tasks = math.ceil(args.spp / args.small_chunk)
        extra = []
        for _ in range(args.rounds):
            local_wall = render(fresh_store(), None, scene, args.spp, args.small_chunk)[0]
            with RemoteRenders(fresh_store(), one, chunk=args.small_chunk) as renders:
                dask_wall = render(None, renders, scene, args.spp, args.small_chunk, one.client)[0]
            extra.append((dask_wall - local_wall) / tasks)
        tiny = RenderStore(reg, Cache(enabled=False), resolution=(1, 1))
        trips = []
        for _ in range(20):
            with RemoteRenders(tiny, one, chunk=1) as renders:
                trips.append(timed_call(lambda: renders.reference(scene, "pathtracer", 0, spp=1).result())[1] / 1e3)
        overhead = max(statistics.median(extra), statistics.median(trips))
        print(f"\nper-task overhead at {args.resolution[0]}x{args.resolution[1]} ({tasks} tasks of "
              f"{args.small_chunk} spp, 1 worker): median {statistics.median(extra) * 1e3:.1f} ms "
              f"[{min(extra) * 1e3:.1f}-{max(extra) * 1e3:.1f}]")
        print(f"round trip of a 1-sample 1x1 task: median {statistics.median(trips) * 1e3:.1f} ms "
              f"[{min(trips) * 1e3:.1f}-{max(trips) * 1e3:.1f}]")

        # ---------------------------------------------------------------- projection
        per_worker = statistics.median(rate["dask-1"])  # one worker with every core of this machine
        per_core = statistics.median(rate["dask-2"]) / cores
        efficiency = min(1.0, statistics.median(ratio))
        pw, ph = args.project
        big_pixels = pw * ph
        for name, res_pixels in ((f"{args.resolution[0]}x{args.resolution[1]}", pixels), (f"{pw}x{ph}", big_pixels)):
            chunk = 20 * overhead * per_worker / res_pixels
            print(f"chunk size for overhead under 5% at {name}: {max(chunk, 1):.2f} samples per task "
                  f"(o = {overhead * 1e3:.1f} ms, r = {per_worker / 1e6:.3f} M paths/s per {cores}-core worker)")
        big_paths = big_pixels * args.project_spp
        print(f"\nprojected wall time of a {pw}x{ph} x {args.project_spp}-spp reference "
              f"({big_paths / 1e9:.2f} G paths) "
              f"at {per_core / 1e6:.3f} M paths/s per core, efficiency {efficiency:.2f}, "
              f"one task per core of {args.project_spp} / cores spp:")
        for n in (cores, 16, 64, 256):
            chunk_spp = max(1, args.project_spp // n)
            tasks_big = math.ceil(args.project_spp / chunk_spp)
            seconds = big_paths / (n * per_core * efficiency) + overhead * tasks_big / n
            print(f"  {n:>4} cores: {seconds / 3600:7.3f} h ({seconds:,.0f} s), {tasks_big} tasks of {chunk_spp} spp; "
                  f"the client receives {tasks_big * big_pixels * 24 / 1e9:.1f} GB of float64 sums")
    finally:
        for executor in clusters.values():
            executor.close()
    return 0


if __name__ == "__main__":
    run(main)
