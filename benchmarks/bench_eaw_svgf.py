"""``eaw`` and ``svgf`` against their peers and their memory floors, in one process, alternating.

For each resolution and thread count, one ``synthetic-moving`` frame (the channels the four
filters read) is filtered by every selected filter in turn, round after round (the order
rotates each round), so that a change of machine load hits all of them alike. Each call is
timed in wall-clock time and in process CPU time (all threads together). ``svgf`` is timed as
``denoise-bench bench`` times it: on frame 1, with the history of frame 0, on a fresh copy of
the filter each call (``--steady`` times it on frame ``--warm`` instead, after ``--warm``
frames: temporal variance everywhere).

The floors are the issue's limit: a kernel that only reads every input buffer the filter
declares (and the frame holds) and writes one output frame, on the same threads. The ratios
are taken round by round (filter time / other's time in the same round) and reported as
median and range.

Usage::

    python benchmarks/bench_eaw_svgf.py --resolution 1280x720 --threads 1,2 --rounds 7
    python benchmarks/bench_eaw_svgf.py --resolution 1280x720,1920x1080 --threads 2 \\
        --filters eaw,svgf,floor_eaw,floor_svgf

``--threads`` sets Numba's threads, OpenCV's (``cv2.setNumThreads``) and OIDN's (device
``numThreads``); the process is started with as many Numba threads as the largest value.

``--baseline REF`` adds ``NAME@REF`` for each selected one of ``eaw``, ``svgf``,
``opencv_jbf``, ``oidn``: the plugin as it was at git revision ``REF`` of this checkout
(extracted to a temporary folder and imported from there), timed in the same rounds, for
before/after figures; the output difference of each against the current plugin (max abs
difference over the image's range) is printed too.

``--memory`` measures, for each selected filter and resolution, the peak extra resident memory
of the filter's first calls at that size (``svgf``: two frames, so its history buffers are in
place; the others: one), its kept buffers and its output included, each filter in a fresh
process (Linux: the peak resident size ``VmHWM`` is reset through ``/proc/self/clear_refs``
after a compile-only call on a 16x16 frame, and the resident size before the calls is
subtracted)::

    python benchmarks/bench_eaw_svgf.py --memory --resolution 1280x720,1920x1080,3840x2160

``--balance`` (Linux) also reads each thread's CPU time (``/proc/self/task/*/stat``, 10 ms
ticks) around the timed calls and prints, per filter, how the work was shared among the threads:
the busiest thread's share and ``total / busiest``, the speed-up over one thread that this
sharing allows on otherwise idle cores (a measure of load balance that a loaded machine does not
disturb, unlike wall-clock time)::

    NUMBA_NUM_THREADS=2 python benchmarks/bench_eaw_svgf.py --threads 2 --filters eaw,svgf --balance

``--cpu-stages`` makes the filters' ``stage_ms`` process CPU time instead of wall-clock time
(the plugins' stage clocks are pointed at ``time.process_time``): on a machine shared with
other work this is the steadier per-stage breakdown; it is meaningful with one thread only.
"""

from __future__ import annotations

import argparse
import copy
import ctypes
import gc
import importlib
import json
import os
import subprocess
import sys
import tempfile
import time
import types
from pathlib import Path

import numpy as np
from numba import get_num_threads, njit, prange, set_num_threads

from harness import load_plugins

#: the channels the four filters read (eaw: color, normal, position; svgf: color, albedo,
#: normal, depth, object_id, motion, indirect, emission; opencv_jbf: color, normal; oidn:
#: color, albedo, normal); the svgf baseline of ``--baseline`` also reads direct
CHANNELS = frozenset({"color", "normal", "position", "albedo", "depth", "object_id", "motion",
                      "direct", "indirect", "emission"})


@njit(parallel=True, cache=True)
def floor_eaw(color, normal, position, out):
    """Read every input ``eaw`` declares, write one frame (the memory floor)."""
    h, w = color.shape[:2]
    for y in prange(h):
        for x in range(w):
            for c in range(3):
                out[y, x, c] = color[y, x, c] + normal[y, x, c] + position[y, x, c]


@njit(parallel=True, cache=True)
def floor_svgf(color, indirect, emission, albedo, normal, depth, object_id, motion, out):
    """Read every input ``svgf`` declares (optional ones included), write one frame."""
    h, w = color.shape[:2]
    for y in prange(h):
        for x in range(w):
            g = depth[y, x] + np.float32(object_id[y, x]) + motion[y, x, 0] + motion[y, x, 1]
            for c in range(3):
                out[y, x, c] = (color[y, x, c] + indirect[y, x, c] + emission[y, x, c] + albedo[y, x, c]
                                + normal[y, x, c] + g)


class Floor:
    """A floor kernel with the filter call signature."""

    def __init__(self, kernel, names):
        self.kernel, self.names, self.out = kernel, names, None

    def __call__(self, frame):
        if self.out is None or self.out.shape != frame["color"].shape:
            self.out = np.empty_like(frame["color"])
        self.kernel(*(frame[n] for n in self.names), self.out)
        return self.out


def thread_cpu() -> dict:
    """CPU seconds (user + system) of each thread of this process, by thread id (Linux)."""
    tick = os.sysconf("SC_CLK_TCK")
    times = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:  # the thread ended
            continue
        times[tid] = (int(fields[11]) + int(fields[12])) / tick  # utime, stime (fields 14, 15)
    return times


def set_threads(n: int, filters: dict) -> None:
    """Numba, OpenCV and OIDN on ``n`` threads."""
    set_num_threads(n)
    try:
        import cv2

        cv2.setNumThreads(n)
    except ImportError:
        pass
    for name, f in filters.items():
        if name.split("@")[0] == "oidn":
            import pyoidn

            device = pyoidn.Device()
            device.set_int("numThreads", n)
            device.commit()
            f._device = device


BASELINE_PLUGINS = ("eaw", "svgf", "opencv_jbf", "oidn")


def baseline_package(ref: str, name: str) -> str:
    """Extract the filter plugin ``name`` as it was at git revision ``ref`` into a temporary
    folder put on ``sys.path``, as the package ``baseline_NAME``; return that package's name."""
    root = Path(__file__).resolve().parents[1]
    folder = Path(tempfile.mkdtemp(prefix="bench-baseline-"))
    package = folder / f"baseline_{name}"
    package.mkdir()
    files = subprocess.run(["git", "ls-tree", "--name-only", ref, f"plugins/filters/{name}/"], cwd=root,
                           capture_output=True, text=True, check=True).stdout.split()
    for path in files:
        if path.endswith(".py"):
            source = subprocess.run(["git", "show", f"{ref}:{path}"], cwd=root, capture_output=True, text=True,
                                    check=True).stdout
            (package / Path(path).name).write_text(source)
    sys.path.insert(0, str(folder))
    return package.name


def baseline_factories(ref: str, names) -> dict:
    """``{"NAME@REF": factory}`` for the selected plugins of :data:`BASELINE_PLUGINS` as they
    were at git revision ``ref`` (:func:`baseline_package`)."""
    factories = {}
    for name in BASELINE_PLUGINS:
        if name in names:
            spec = importlib.import_module(baseline_package(ref, name)).register_filters()[0]
            factories[f"{name}@{ref}"] = spec.factory
    return factories


def build(reg, names, baselines):
    """name -> filter (temporal ones are primed and copied per call by the caller)."""
    filters = {}
    for name in names:
        if name == "floor_eaw":
            filters[name] = Floor(floor_eaw, ("color", "normal", "position"))
        elif name == "floor_svgf":
            filters[name] = Floor(floor_svgf, ("color", "indirect", "emission", "albedo", "normal", "depth",
                                               "object_id", "motion"))
        elif name in reg.filters:
            filters[name] = reg.filters[name].factory(backend="cpu")
        elif name in baselines:
            filters[name] = baselines[name](backend="cpu")
        else:
            print(f"{name}: not registered, skipped")
    return filters


def _status_kib(key: str) -> int:
    """A ``/proc/self/status`` entry in KiB (``VmRSS:``, ``VmHWM:``)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key):
                return int(line.split()[1])
    raise KeyError(key)


def memory_child(name: str, w: int, h: int, scene_name: str) -> None:
    """Print the peak extra resident KiB of ``name``'s first calls at ``w`` x ``h`` (JSON)."""
    reg = load_plugins()
    renderer = reg.renderers["synthetic"].factory()
    scene = reg.scenes[scene_name].factory()
    filt = build(reg, [name], {})[name]
    filt(renderer.render(scene, 0, spp=1, seed=0, channels=CHANNELS, resolution=(16, 16)))  # compile
    count = 2 if name == "svgf" else 1
    frames = [renderer.render(scene, k, spp=1, seed=0, channels=CHANNELS, resolution=(w, h))
              for k in range(count)]
    gc.collect()
    ctypes.CDLL("libc.so.6").malloc_trim(0)  # freed heap pages would hide the filter's own
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # the peak resident size (VmHWM) starts again from the current one
    before = _status_kib("VmRSS:")
    for frame in frames:
        filt(frame)
    print(json.dumps({"kib": _status_kib("VmHWM:") - before}))


def memory_table(names, resolutions, scene_name: str) -> None:
    """One fresh process per filter and resolution (see ``--memory``); a Markdown table."""
    print("\n| filter | resolution | peak extra memory | bytes per pixel | RGB float32 frames |")
    print("|---|---|---|---|---|")
    for w, h in resolutions:
        for name in names:
            proc = subprocess.run([sys.executable, __file__, "--memory-child", name, "--resolution", f"{w}x{h}",
                                   "--scene", scene_name], capture_output=True, text=True)
            if proc.returncode:
                print(f"| {name} | {w}x{h} | error: {proc.stderr.strip()[-200:]} | | |")
                continue
            kib = json.loads(proc.stdout.strip().splitlines()[-1])["kib"]
            per_pixel = kib * 1024 / (w * h)
            print(f"| {name} | {w}x{h} | {kib / 1024:.0f} MiB | {per_pixel:.0f} | {per_pixel / 12:.1f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", default="1280x720", help="comma-separated WxH list")
    ap.add_argument("--threads", default="", help="comma-separated thread counts (default: all)")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--filters", default="eaw,svgf,opencv_jbf,oidn,floor_eaw,floor_svgf")
    ap.add_argument("--scene", default="synthetic-moving")
    ap.add_argument("--steady", action="store_true", help="time svgf after --warm frames")
    ap.add_argument("--warm", type=int, default=6)
    ap.add_argument("--baseline", default="", help="git revision whose plugins are timed too")
    ap.add_argument("--cpu-stages", action="store_true", help="stage_ms in process CPU time (one thread)")
    ap.add_argument("--balance", action="store_true", help="per-thread CPU time of the timed calls (Linux)")
    ap.add_argument("--memory", action="store_true", help="peak extra memory per filter, fresh processes")
    ap.add_argument("--memory-child", default="", help=argparse.SUPPRESS)
    args = ap.parse_args()
    resolutions = [tuple(int(v) for v in res.split("x")) for res in args.resolution.split(",")]
    if args.memory_child:
        memory_child(args.memory_child, *resolutions[0], args.scene)
        return
    if args.memory:
        memory_table([n for n in args.filters.split(",") if n and not n.startswith("floor")], resolutions,
                     args.scene)
        return
    reg = load_plugins()
    renderer = reg.renderers["synthetic"].factory()
    scene = reg.scenes[args.scene].factory()
    names = [n for n in args.filters.split(",") if n]
    baselines = baseline_factories(args.baseline, names) if args.baseline else {}
    names += list(baselines)
    if args.cpu_stages:
        cpu_clock = types.SimpleNamespace(perf_counter=time.process_time)
        for module in ("plugins.filters.eaw.cpu", "plugins.filters.svgf.pipeline", "baseline_eaw.cpu",
                       "baseline_eaw.filter", "baseline_svgf.pipeline"):
            try:
                importlib.import_module(module).time = cpu_clock
            except ImportError:
                pass
    threads = [int(t) for t in args.threads.split(",") if t] or [get_num_threads()]
    for w, h in resolutions:
        count = args.warm + 1 if args.steady else 2
        frames = [renderer.render(scene, k, spp=1, seed=0, channels=CHANNELS, resolution=(w, h))
                  for k in range(count)]
        timed = frames[-1]
        filters = build(reg, names, baselines)
        temporal = {n for n in filters if n.split("@")[0] == "svgf"}
        for n in threads:
            set_threads(n, filters)
            primed = {}
            outs = {}
            for name, f in filters.items():
                if name in temporal:
                    f.reset()
                    for fr in frames[:-1]:
                        f(fr)
                    primed[name] = f
                outs[name] = (copy.deepcopy(f) if name in primed else f)(timed)  # compile / warm up
            wall = {k: [] for k in filters}
            cpu = {k: [] for k in filters}
            stages = {k: [] for k in filters}
            shares = {k: {} for k in filters}
            order = list(filters)
            for r in range(args.rounds):
                for name in order[r % len(order):] + order[:r % len(order)]:
                    f = copy.deepcopy(primed[name]) if name in primed else filters[name]
                    before = thread_cpu() if args.balance else {}
                    t0, c0 = time.perf_counter(), time.process_time()
                    f(timed)
                    wall[name].append((time.perf_counter() - t0) * 1e3)
                    cpu[name].append((time.process_time() - c0) * 1e3)
                    for tid, t in (thread_cpu() if args.balance else {}).items():
                        shares[name][tid] = shares[name].get(tid, 0.0) + t - before.get(tid, 0.0)
                    stages[name].append(dict(getattr(f, "stage_ms", {}) or {}))
            span = float(timed["color"].max() - timed["color"].min())
            for base in baselines:
                now = base.split("@")[0]
                if base in outs and now in outs:
                    diff = np.abs(outs[base].astype(np.float64) - outs[now]).max() / span
                    print(f"{now} against {base}: max abs difference / range of the input {diff:.2e}")
            print(f"\n{w}x{h}, {n} thread(s), {args.rounds} rounds, scene {args.scene}"
                  f"{', svgf steady state' if args.steady else ''}; ms per frame")
            width = max(16, *(len(name) for name in filters))
            print(f"{'filter':{width}s} {'wall min':>9s} {'wall med':>9s} {'cpu min':>9s} {'cpu med':>9s}")
            for name in filters:
                print(f"{name:{width}s} {min(wall[name]):9.1f} {np.median(wall[name]):9.1f} "
                      f"{min(cpu[name]):9.1f} {np.median(cpu[name]):9.1f}")
            # (a, b): b's time over a's, round by round ("eaw / floor_eaw" is x_of_floor)
            pairs = [("eaw", "opencv_jbf"), ("floor_eaw", "eaw"), ("svgf", "oidn"), ("floor_svgf", "svgf"),
                     ("svgf", "eaw")] + [(n.split("@")[0], n) for n in baselines]
            for a, b in pairs:
                if a in filters and b in filters:
                    for label, t in (("wall", wall), ("cpu", cpu)):
                        ratio = np.array(t[b]) / np.array(t[a])
                        print(f"  {b} / {a} ({label}, per round): median {np.median(ratio):.2f}, "
                              f"range {ratio.min():.2f}-{ratio.max():.2f}")
            for name in filters:
                busy = sorted((t for t in shares[name].values() if t > 0), reverse=True)
                if busy:
                    total = sum(busy)
                    print(f"  {name} thread CPU over the rounds: {', '.join(f'{t:.2f}' for t in busy[:n + 1])} s; "
                          f"busiest share {busy[0] / total:.2f}, total / busiest {total / busy[0]:.2f}")
            for name in filters:
                if stages[name] and stages[name][0]:
                    keys = stages[name][0]
                    text = ", ".join(f"{k} {np.median([s[k] for s in stages[name]]):.1f}" for k in keys)
                    print(f"  {name} stages (median ms): {text}")


if __name__ == "__main__":
    main()
