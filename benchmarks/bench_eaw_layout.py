"""Layout and skipping measurements of the ``eaw`` CPU backend.

Times the five à-trous passes alone (the filter's inner part) on one ``synthetic-edges`` frame
(sky on top) for several row strides of the padded planes, and with / without skipping the
pixels that have nothing to filter. Variants are interleaved round by round, so that a change
of machine load hits all of them alike; the table gives min and median of wall-clock ms per
frame and of process CPU ms (both threads together).

``--per-pass`` also prints, for the default stride with skipping, the median wall-clock ms of
each pass (hole spacing 1, 2, 4, ...; the last one also writes the output frame).

Usage::

    python benchmarks/bench_eaw_layout.py [--resolution 1280x720] [--rounds 7] [--per-pass]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from numba import get_num_threads

from harness import load_plugins
from plugins.filters.eaw import cpu, layout
from plugins.filters.eaw.params import EAWParams, b3_kernel


def prepare(frame, params, stride, skip):
    """Packed buffers (with their runs) and the pixel classes for one frame."""
    buf = layout.Buffers(frame.height, frame.width, params.halo(), stride)
    layout.prepare(frame, params, buf)
    if not skip:  # every pixel filtered (the background too): timing only
        buf.state[:] = layout.ACTIVE
        buf.run_count[:] = 1
        buf.runs[:, 0] = (0, frame.width)
        buf.row_surface[:] = 1
    return buf, buf.state


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", default="1280x720")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--per-pass", action="store_true", help="also time each pass of the default variant")
    args = ap.parse_args()
    w, h = (int(v) for v in args.resolution.split("x"))
    reg = load_plugins()
    renderer = reg.renderers["synthetic"].factory()
    scene = reg.scenes["synthetic-edges"].factory()
    frame = renderer.render(scene, 0, spp=1, seed=0, channels=frozenset({"color", "normal", "position"}),
                            resolution=(w, h))
    params = EAWParams()
    halo = params.halo()
    taps, coefficients = b3_kernel(), params.coefficients()
    tight = w + 2 * halo
    variants = {
        f"stride {layout.padded_stride(w, halo)} (odd x 16, default), skip": (None, True),
        f"stride {tight} (no padding), skip": (tight, True),
        f"stride {tight + (-tight) % 512} (multiple of 2 KiB), skip": (tight + (-tight) % 512, True),
        f"stride {layout.padded_stride(w, halo)}, no skip": (None, False),
    }
    prepared = {name: prepare(frame, params, *v) for name, v in variants.items()}
    color = frame["color"]
    for buf, _ in prepared.values():
        cpu.iterate(buf, coefficients, taps, color, 1.0)  # compile / warm up
    wall = {name: [] for name in variants}
    proc = {name: [] for name in variants}
    for _ in range(args.rounds):
        for name, (buf, _) in prepared.items():
            t0, c0 = time.perf_counter(), time.process_time()
            cpu.iterate(buf, coefficients, taps, color, 1.0)
            wall[name].append((time.perf_counter() - t0) * 1e3)
            proc[name].append((time.process_time() - c0) * 1e3)
    active = np.mean(prepared[next(iter(prepared))][1] == layout.ACTIVE)
    print(f"{w}x{h}, {params.iterations} passes, {get_num_threads()} threads, active pixels {active:.1%}")
    print(f"{'variant':48s} {'wall min':>9s} {'wall med':>9s} {'cpu min':>9s} {'cpu med':>9s}")
    for name in variants:
        print(f"{name:48s} {min(wall[name]):9.1f} {np.median(wall[name]):9.1f} "
              f"{min(proc[name]):9.1f} {np.median(proc[name]):9.1f}")
    if args.per_pass:
        per_pass(prepared[next(iter(prepared))][0], coefficients, taps, color, args.rounds)


def per_pass(buf, coefficients, taps, color, rounds: int) -> None:
    """Print the median wall-clock ms of each à-trous pass (``cpu.atrous_pass`` timed call by call)."""
    kernel = cpu.atrous_pass
    times: dict[int, list] = {}

    def timed(*args):
        t0 = time.perf_counter()
        kernel(*args)
        times.setdefault(args[9], []).append((time.perf_counter() - t0) * 1e3)  # args[9]: the hole spacing

    cpu.atrous_pass = timed
    try:
        for _ in range(rounds):
            cpu.iterate(buf, coefficients, taps, color, 1.0)
    finally:
        cpu.atrous_pass = kernel
    print("ms per pass (hole spacing: median): "
          + ", ".join(f"{step}: {np.median(v):.2f}" for step, v in sorted(times.items())))


if __name__ == "__main__":
    main()
