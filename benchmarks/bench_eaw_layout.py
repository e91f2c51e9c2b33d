"""Layout and skipping measurements of the ``eaw`` CPU backend.

Times the five à-trous passes alone (the filter's inner part) on one ``synthetic-edges`` frame
(sky on top) for several row strides of the padded planes, and with / without skipping the
pixels that have nothing to filter. Variants take turns call by call
(:func:`harness.timer.alternate`), so that a change of machine load hits all of them alike; the
table gives median [min-max] of wall-clock ms per frame and of process CPU ms (all threads).

``--per-pass`` also prints, for the default stride with skipping, the median wall-clock ms of
each pass (hole spacing 1, 2, 4, ...; the last one also writes the output frame).

Usage::

    python benchmarks/bench_eaw_layout.py [--resolution 1280x720] [--rounds 7] [--per-pass]

The whole filter against its peers, floors and earlier revisions is ``denoise-bench bench eaw
--rounds N [--baseline REV]``.
"""

from __future__ import annotations

import numpy as np
from common import alternate, integer, parser, resolution, run, time_table, timed_call
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


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--resolution", type=resolution, default=(1280, 720))
    ap.add_argument("--rounds", type=integer(1), default=7)
    ap.add_argument("--per-pass", action="store_true", help="also time each pass of the default variant")
    args = ap.parse_args(argv)
    w, h = args.resolution
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
    calls = {name: (lambda buf=buf: cpu.iterate(buf, coefficients, taps, color, 1.0))
             for name, (buf, _) in prepared.items()}
    result = alternate(calls, args.rounds)
    active = np.mean(prepared[next(iter(prepared))][1] == layout.ACTIVE)
    print(f"{w}x{h}, {params.iterations} passes, {get_num_threads()} threads, active pixels {active:.1%}")
    print(time_table(result, width=48))
    if args.per_pass:
        per_pass(prepared[next(iter(prepared))][0], coefficients, taps, color, args.rounds)
    return 0


def per_pass(buf, coefficients, taps, color, rounds: int) -> None:
    """Print the median wall-clock ms of each à-trous pass (``cpu.atrous_pass`` timed call by call)."""
    kernel = cpu.atrous_pass
    times: dict[int, list] = {}

    def timed(*args):
        _, ms, _ = timed_call(lambda: kernel(*args))
        times.setdefault(args[9], []).append(ms)  # args[9]: the hole spacing

    cpu.atrous_pass = timed
    try:
        for _ in range(rounds):
            cpu.iterate(buf, coefficients, taps, color, 1.0)
    finally:
        cpu.atrous_pass = kernel
    print("ms per pass (hole spacing: median): "
          + ", ".join(f"{step}: {np.median(v):.2f}" for step, v in sorted(times.items())))


if __name__ == "__main__":
    run(main)
