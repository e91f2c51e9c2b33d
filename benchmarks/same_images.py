"""Whether the path tracer renders the third-party Mitsuba scenes bit for bit as an earlier copy did.

    python benchmarks/same_images.py --baseline REV [--width 64 --height 36 --spp 4 --max-depth 8]
    python benchmarks/same_images.py --baseline REV --builtin

Loads ``classroom``, ``living-room`` and ``sponza`` from ``../shared/scenes`` with this project's
Mitsuba loader and with the one at git revision REV (imported beside it: ``benchmarks/common.py``),
renders each with both path tracers (same seed, spp and resolution) and prints, per scene,
whether colour and variance are bit-identical and the largest difference. Used where a change
must leave those scenes' images (and so their region ratios to Mitsuba 3, ``docs/pathtracer.md``)
as they were.

``--builtin``: instead, every registered ``mesh`` scene (first and last frame, at most 128x96,
8 spp, seed 2), both renderers on the same scene object; colour, variance, visibility and the
direct part compared, so that the default run's leaderboard is known to be unchanged.
"""

from __future__ import annotations

import warnings

import numpy as np
from bench_pathtracer import baseline
from common import SHARED_SCENES, integer, parser, run

from plugins.renderers.pathtracer import PathTracer
from plugins.scenes.mitsuba import load

SCENES = ("classroom", "living-room", "sponza")


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--baseline", required=True, metavar="REV", help="git revision to compare with")
    ap.add_argument("--width", type=integer(1), default=64)
    ap.add_argument("--height", type=integer(1), default=36)
    ap.add_argument("--spp", type=integer(1), default=4)
    ap.add_argument("--max-depth", type=integer(1), default=8)
    ap.add_argument("--builtin", action="store_true", help="compare the registered mesh scenes instead")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    with baseline(args.baseline) as (old_tracer, old_load, _):
        if args.builtin:
            builtin(old_tracer)
        else:
            shared(args, old_tracer, old_load)
    return 0


def shared(args, old_tracer, old_load) -> None:
    """The third-party scenes rendered by both path tracers, each loaded by its own loader."""
    root = SHARED_SCENES
    for name in SCENES:
        folder = root / name
        if not folder.is_dir():
            print(f"{name}: not found beside the project, skipped")
            continue
        kwargs = dict(spp=args.spp, seed=1, channels={"variance"}, resolution=(args.width, args.height))
        new = PathTracer(max_depth=args.max_depth).render(load(folder), 0, **kwargs)
        old = old_tracer(max_depth=args.max_depth).render(old_load(folder), 0, **kwargs)
        same = all(np.array_equal(new[k], old[k], equal_nan=True) for k in ("color", "variance"))
        diff = float(np.nanmax(np.abs(new["color"].astype(np.float64) - old["color"])))
        print(f"{name}: {'bit-identical' if same else 'different'} (largest colour difference {diff:.3g})")


def builtin(old_tracer) -> None:
    """Every registered mesh scene rendered by both path tracers: bit-identical or not."""
    from harness import load_plugins

    channels = ("color", "variance", "visibility", "direct")
    for name, spec in sorted(load_plugins().scenes.items()):
        try:
            scene = spec.factory()
        except (OSError, ValueError) as exc:  # a third-party scene not beside the project
            print(f"{name}: skipped ({exc})")
            continue
        if scene.kind != "mesh":
            continue
        w, h = scene.resolution
        for frame in sorted({0, scene.frame_count - 1}):
            kwargs = dict(spp=8, seed=2, channels=set(channels), resolution=(min(w, 128), min(h, 96)))
            new = PathTracer().render(scene, frame, **kwargs)
            old = old_tracer().render(scene, frame, **kwargs)
            same = all(np.array_equal(new[k], old[k], equal_nan=True) for k in channels)
            print(f"{name} frame {frame}: {'bit-identical' if same else 'different'}", flush=True)


if __name__ == "__main__":
    run(main)
