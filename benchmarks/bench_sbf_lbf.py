"""Speed of ``sbf`` and ``lbf`` against their floor and their peers, measured in one process.

For each resolution, one ``synthetic-moving`` frame (1 spp, seed 0, the frame
``denoise-bench bench`` uses) goes through every entry once per round, entries alternating
within a round, for ``--rounds`` rounds after a warm-up call. Per entry: wall-clock ms (median,
min, max) and process CPU ms (all threads; robust on a machine shared with other jobs).

* ``floor_sbf`` / ``floor_lbf``: a Numba kernel that reads every input buffer the filter
  declares (sbf: colour, variance, normal, albedo, depth, spp; lbf: colour, variance, normal,
  albedo, position, visibility, spp) and writes one output frame, parallel over rows like the
  filters. ``x_of_floor`` = filter ms / floor ms, taken per round and given as a range.
* ``x_vs_oidn`` and ``x_vs_opencv_jbf`` = filter ms / peer ms per round (above 1: slower).
* ``--threads 1,2``: the filters again with ``numba.set_num_threads(n)``, alternating, and
  ``speedup_2_vs_1`` = (1-thread ms) / (2-thread ms) per round.
* ``--stages``: single-thread process CPU ms of each stage (sbf: the pass with and without
  the SURE smoothing; lbf: signals, features + network, bilateral).
* ``--memory``: peak extra resident memory of one call of each filter at each resolution,
  measured in a fresh process (Linux: the peak resident size ``VmHWM`` is reset through
  ``/proc/self/clear_refs`` before the call and read after it, minus the resident size before;
  kernels warmed up on a 16x16 frame first), in bytes per pixel and in full RGB float32 frames
  (12 B/pixel). The output frame itself (12 B/pixel) is included.

Usage::

    python benchmarks/bench_sbf_lbf.py [--resolutions 1280x720,1920x1080] [--rounds 5]
        [--threads 1,2] [--memory] [--stages]
"""

from __future__ import annotations

import argparse
import json
import platform
import resource
import subprocess
import sys
import time

import numba
import numpy as np
from numba import njit, prange

from harness import CHANNELS, load_plugins

TARGETS = ("sbf", "lbf")
PEERS = ("oidn", "opencv_jbf")
READS = {
    "sbf": ("color", "variance", "normal", "albedo", "depth", "spp"),
    "lbf": ("color", "variance", "normal", "albedo", "position", "visibility", "spp"),
}


@njit(parallel=True, cache=True)
def _floor(color, variance, normal, albedo, depth, position, visibility, spp, out, slots):
    """Read each given buffer once and write ``out`` (rows dealt cyclically to the workers)."""
    h, w, _ = color.shape
    for s in prange(slots):
        for i in range(s, h, slots):
            for j in range(w):
                extra = depth[i, j] + visibility[i, j] + np.float32(spp[i, j])
                for c in range(3):
                    out[i, j, c] = (color[i, j, c] + variance[i, j, c] + normal[i, j, c]
                                    + albedo[i, j, c] + position[i, j, c] + extra)


class Floor:
    """The floor of a filter: reads its declared inputs, writes one frame."""

    def __init__(self, name: str):
        self.reads = READS[name]

    def __call__(self, frame):
        h, w = frame.shape
        zero3 = np.zeros((1, 1, 3), np.float32)
        zero1 = np.zeros((1, 1), np.float32)

        def get(name, empty):
            if name not in self.reads:
                return np.broadcast_to(empty, (h, w) + empty.shape[2:])
            return frame[name]

        out = np.empty((h, w, 3), np.float32)
        _floor(frame["color"], frame["variance"], get("normal", zero3), get("albedo", zero3),
               get("depth", zero1), get("position", zero3), get("visibility", zero1),
               get("spp", np.zeros((1, 1), np.int32)), out, numba.get_num_threads())
        return out


def render(reg, width: int, height: int):
    renderer = reg.renderers["synthetic"].factory()
    scene = reg.scenes["synthetic-moving"].factory()
    return renderer.render(scene, 0, spp=1, seed=0, channels=frozenset(CHANNELS),
                           resolution=(width, height))


def build(reg, name):
    if name.startswith("floor_"):
        return Floor(name[len("floor_"):])
    spec = reg.filters[name]
    return spec.factory(backend="cpu", **dict(spec.params))


def timed(fn, frame):
    c0 = time.process_time()
    t0 = time.perf_counter()
    fn(frame)
    return (time.perf_counter() - t0) * 1e3, (time.process_time() - c0) * 1e3


def rounds(entries: dict, frame, n: int, threads=None) -> dict:
    """``{name: [(wall_ms, cpu_ms), ...]}``, entries alternating within each round."""
    times = {name: [] for name in entries}
    for name, fn in entries.items():  # warm-up / compile
        if threads:
            numba.set_num_threads(threads[name])
        fn(frame)
    for _ in range(n):
        for name, fn in entries.items():
            if threads:
                numba.set_num_threads(threads[name])
            times[name].append(timed(fn, frame))
    if threads:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    return times


def _range(values) -> str:
    v = np.asarray(values)
    return f"{np.median(v):.2f} ({v.min():.2f}-{v.max():.2f})"


def speed_table(reg, frame, n: int) -> None:
    names = [f for f in TARGETS] + [f"floor_{f}" for f in TARGETS] + [p for p in PEERS
                                                                     if p in reg.filters]
    entries = {name: build(reg, name) for name in names}
    times = rounds(entries, frame, n)
    wall = {k: np.array([t[0] for t in v]) for k, v in times.items()}
    cpu = {k: np.array([t[1] for t in v]) for k, v in times.items()}
    print("| entry | wall ms median (min-max) | CPU ms median | x_of_floor (wall) | "
          "x_vs_oidn (wall) | x_vs_opencv_jbf (wall) | x_vs_oidn (CPU) |")
    print("|---|---|---|---|---|---|---|")
    for name in names:
        row = [name, f"{np.median(wall[name]):.0f} ({wall[name].min():.0f}-{wall[name].max():.0f})",
               f"{np.median(cpu[name]):.0f}"]
        base = name if name in TARGETS else None
        row.append(_range(wall[name] / wall[f"floor_{base}"]) if base else "-")
        for peer in PEERS:
            row.append(_range(wall[name] / wall[peer]) if peer in wall else "-")
        row.append(_range(cpu[name] / cpu["oidn"]) if "oidn" in cpu else "-")
        print("| " + " | ".join(row) + " |")
    for name in TARGETS:
        stages = getattr(entries[name], "stage_ms", {})
        print(f"\n{name} stages of the last call (wall ms): "
              + ", ".join(f"{k} {v:.0f}" for k, v in stages.items()))


def thread_table(reg, frame, n: int, counts) -> None:
    entries, threads = {}, {}
    for name in TARGETS:
        for t in counts:
            key = f"{name}@{t}"
            entries[key] = build(reg, name)
            threads[key] = t
    times = rounds(entries, frame, n, threads)
    print("\n| filter | threads | wall ms median (min-max) | CPU ms median | speedup vs 1 thread "
          "(wall, per round) |")
    print("|---|---|---|---|---|")
    for key, vals in times.items():
        name, t = key.split("@")
        wall = np.array([v[0] for v in vals])
        cpu = np.array([v[1] for v in vals])
        one = np.array([v[0] for v in times[f"{name}@{counts[0]}"]])
        print(f"| {name} | {t} | {np.median(wall):.0f} ({wall.min():.0f}-{wall.max():.0f}) | "
              f"{np.median(cpu):.0f} | {_range(one / wall)} |")


_MEMORY_SCRIPT = """
import json, sys
import numpy as np
sys.path.insert(0, {here!r})
from bench_sbf_lbf import build, render
from harness import load_plugins
reg = load_plugins()
name, w, h = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
filt = build(reg, name)
filt(render(reg, 16, 16))
frame = render(reg, w, h)
def status(key):
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1])
import ctypes, gc
gc.collect()
ctypes.CDLL("libc.so.6").malloc_trim(0)  # freed heap pages would hide the filter's own
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")  # resets the peak resident size (VmHWM) to the current one
before = status("VmRSS:")
filt(frame)
print(json.dumps({{"kib": status("VmHWM:") - before}}))
"""


def memory_table(resolutions) -> None:
    from pathlib import Path

    here = str(Path(__file__).resolve().parent)
    print("\n| filter | resolution | peak extra memory of one call | B/pixel | full RGB frames |")
    print("|---|---|---|---|---|")
    for w, h in resolutions:
        for name in TARGETS + ("oidn",):
            proc = subprocess.run([sys.executable, "-c", _MEMORY_SCRIPT.format(here=here), name,
                                   str(w), str(h)], capture_output=True, text=True)
            if proc.returncode:
                print(f"| {name} | {w}x{h} | error: {proc.stderr.strip()[-200:]} | | |")
                continue
            kib = json.loads(proc.stdout.strip().splitlines()[-1])["kib"]
            per_px = kib * 1024 / (w * h)
            print(f"| {name} | {w}x{h} | {kib / 1024:.0f} MiB | {per_px:.0f} | {per_px / 12:.1f} |")


def stage_table(reg, frame, n: int) -> None:
    """Single-thread process CPU ms of each stage (median of ``n``), both filters."""
    from plugins.filters.lbf import cpu as lbf_cpu
    from plugins.filters.lbf.features import gather_inputs

    numba.set_num_threads(1)
    sbf, lbf = build(reg, "sbf"), build(reg, "lbf")
    sbf(frame)
    lbf(frame)
    inputs = gather_inputs(frame)
    den = lbf.denoiser
    w = frame.shape[1]

    def cpu_ms(fn, *args):
        c0 = time.process_time()
        value = fn(*args)
        return (time.process_time() - c0) * 1e3, value

    rows = {}
    for _ in range(n):
        total, _ = cpu_ms(sbf, frame)
        rows.setdefault("sbf: whole call", []).append(total)
        p = sbf.params
        try:  # the pass without SURE smoothing (1x1 table): bank + SURE + argmin only
            object.__setattr__(p, "sure_scale", 0.0)
            bank, _ = cpu_ms(sbf, frame)
        finally:
            object.__setattr__(p, "sure_scale", 4.0)
        rows.setdefault("sbf: features + bank + SURE (no smoothing)", []).append(bank)
        rows.setdefault("sbf: SURE smoothing + selection (difference)", []).append(total - bank)
        feats = sbf.stage_ms["features"]
        rows.setdefault("sbf: features (pack, variance; wall)", []).append(feats)
        t1, planes = cpu_ms(den._signals, inputs, lbf.radius)
        sp, cp, vp, inside, pad, hh, aux = planes
        t2, params = cpu_ms(den._network, sp[:, :, pad:pad + w], aux, hh)
        out = np.empty(frame["color"].shape, np.float32)
        t3, _ = cpu_ms(lbf_cpu._filter, sp, cp, vp, inside, params, lbf.radius,
                       np.float32(1e4), np.float32(1.0), pad, out, 1)
        rows.setdefault("lbf: signals", []).append(t1)
        rows.setdefault("lbf: features + network", []).append(t2)
        rows.setdefault("lbf: bilateral", []).append(t3)
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    print("\n| stage (1 thread) | CPU ms median (min-max) |")
    print("|---|---|")
    for name, vals in rows.items():
        v = np.asarray(vals)
        print(f"| {name} | {np.median(v):.0f} ({v.min():.0f}-{v.max():.0f}) |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolutions", default="1280x720,1920x1080")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--threads", default="1,2", help="thread counts to compare ('' to skip)")
    ap.add_argument("--memory", action="store_true")
    ap.add_argument("--stages", action="store_true", help="single-thread CPU ms per stage")
    args = ap.parse_args()
    resolutions = [tuple(int(v) for v in r.split("x")) for r in args.resolutions.split(",")]
    cpu_model = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo")
                      if line.startswith("model name")), platform.processor())
    print(f"CPU {cpu_model}, {numba.config.NUMBA_NUM_THREADS} Numba threads, numba "
          f"{numba.__version__}, numpy {np.__version__}, {args.rounds} rounds, "
          f"load average {' '.join(f'{x:.1f}' for x in __import__('os').getloadavg())}")
    reg = load_plugins()
    for w, h in resolutions:
        frame = render(reg, w, h)
        print(f"\n### {w}x{h}\n")
        speed_table(reg, frame, args.rounds)
        if args.threads:
            thread_table(reg, frame, args.rounds, [int(t) for t in args.threads.split(",")])
        if args.stages:
            stage_table(reg, frame, args.rounds)
    if args.memory:
        memory_table(resolutions)
    usage = resource.getrusage(resource.RUSAGE_SELF)
    print(f"\nprocess: {usage.ru_utime:.0f} s user, {usage.ru_stime:.0f} s system")


if __name__ == "__main__":
    main()
