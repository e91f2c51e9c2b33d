"""Throughput of the ``pathtracer`` renderer, and of Mitsuba 3 on the same classroom scene.

Usage::

    python benchmarks/bench_pathtracer.py [--width 1280] [--height 720] [--spp 1] [--max-depth 5]
                                          [--repeats 3] [--scenes atrium classroom] [--no-mitsuba]
                                          [--baseline REV]
    python benchmarks/bench_pathtracer.py --ratios [--width 160 --height 90 --spp 256 --max-depth 8]
                                          [--mitsuba-spp N] [--baseline REV] [--relmse]
                                          [--mitsuba-variant fastest|llvm_ad_rgb|scalar_rgb]
    python benchmarks/bench_pathtracer.py --threads 1 2 --no-mitsuba [--scenes classroom]

``--baseline REV``: the path tracer and the Mitsuba loader as they were at git revision REV
(extracted to a temporary folder and imported beside the current ones: ``benchmarks/common.py``);
the earlier path tracer renders the scene as its own loader loads it, and its frames are timed
too, alternating with ours and Mitsuba's frame by frame in this one process, so all three see the
same machine load; the ratio ours / baseline is printed per frame pair (wall and CPU time; with
``NUMBA_NUM_THREADS=1`` and ``--no-mitsuba`` this isolates the path kernel from thread scheduling
on a shared machine).

``--threads N [N ...]``: our path tracer's frames with each of these Numba thread counts
(``numba.set_num_threads``), alternating frame by frame in this one process, labelled
``pathtracer/Nt``; the machine must have at least the largest count of CPUs.

``--ratios``: instead of timing, converged images of the third-party scenes (``--scenes``,
default classroom, living-room, sponza) by both renderers, and the ratio harness / Mitsuba 3 of
the mean of each region of a 4x4 grid (RGB averaged): median, minimum and maximum, and the
ratio of the whole image. The harness's image is its reference (pixel-area samples, as Mitsuba
integrates the pixel with its ``box`` filter). With ``--relmse`` also the relMSE of the harness's
pixel-area and pixel-centre references against Mitsuba 3's image, beside the relMSE of a second
Mitsuba 3 image (seed 1) against it: Mitsuba's own seed-to-seed noise at the same samples.
Mitsuba 3 gets ``diffuse`` for ``roughdiffuse`` and the harness's
``roughplastic`` for ``phong`` (Mitsuba 3 has neither), so that the ratios measure the materials;
a ``sun``/``sky``/``sunsky`` emitter becomes Mitsuba 3's own ``sunsky`` with the parameters that
the harness's loader read (``Scene.params["sunsky"]``: Mitsuba 3's semantics, see
``plugins/scenes/mitsuba/sun_sky.py``). With ``--baseline REV`` the earlier revision's loader and
path tracer render each scene too, and their ratios to the same Mitsuba 3 image are printed.

For each scene: paths per second and milliseconds per ``spp``-sample frame (median of
``repeats`` timed frames after one warm-up frame, the renderers taking turns frame by frame,
:func:`harness.timer.alternate`; wall clock plus the process CPU time, which is steadier on a
shared machine). A timed frame is a complete render:
primary rays, first hits and the path samples (the BVH is built once per scene, during the
warm-up, as Mitsuba builds its own when loading). Then, in the same process, Mitsuba 3
(its fastest CPU variant by default, ``--mitsuba-variant fastest``: ``llvm_ad_rgb`` where an LLVM
works, which needs ``DRJIT_LIBLLVM_PATH`` naming a working libLLVM, else ``scalar_rgb``; the output
says which and why; Dr.Jit's threads set to Numba's count; ``path`` integrator, same resolution,
spp, ``max_depth`` and Russian roulette depth) renders ``../shared/scenes/classroom/scene.xml``
with its sun and sky as Mitsuba 3's ``sunsky`` of the parameters the harness read (as in
``--ratios``). The third-party scene folder
is found next to the project root and the benchmark skips it, with a message, when it is absent.
"""

from __future__ import annotations

import math
import os
import re
import statistics
import tempfile
import warnings
from contextlib import contextmanager, nullcontext
from pathlib import Path

import numba
import numpy as np
from common import SHARED_SCENES, alternate, baseline_packages, integer, parser, run

from harness import load_plugins

SCENES = SHARED_SCENES


def harness_scene(registry, name: str):
    if name in registry.scenes:
        return registry.scenes[name].factory()
    folder = SCENES / name
    if folder.is_dir():
        return registry.open_scene(folder)
    return None


def frame_of(renderer_class, scene, args, threads=None):
    """A function rendering one complete frame (primary rays and first hits included), with
    ``threads`` Numba threads (None: as set)."""
    renderer = renderer_class(max_depth=args.max_depth, rr_depth=args.rr_depth)
    size = (args.width, args.height)

    def frame():
        if threads is not None:
            numba.set_num_threads(threads)
        renderer._setups.clear()
        renderer.render(scene, 0, spp=args.spp, seed=0, resolution=size)

    return frame


@contextmanager
def baseline(rev: str):
    """(``PathTracer`` class, Mitsuba ``load`` function, path tracer package) as they were at git
    revision ``rev``."""
    with baseline_packages(rev, ["plugins/renderers/pathtracer", "plugins/scenes/mitsuba"]) as (tracer, loader):
        yield tracer.PathTracer, loader.load, tracer


def _camel(name: str) -> str:
    head, *rest = name.split("_")
    return head + "".join(p.title() for p in rest)


def _sunsky_xml(record: dict) -> str:
    """Mitsuba 3's own ``sunsky`` emitter with the parameters the harness's loader read (``Scene.params["sunsky"]``)."""
    d, m, albedo = record["sun_direction"], record["to_world"], record["albedo"]
    matrix = " ".join(f"{v:.9g}" for v in [*m[0], 0.0, *m[1], 0.0, *m[2], 0.0, 0.0, 0.0, 0.0, 1.0])
    albedo = (f'<float name="albedo" value="{albedo[0]:.9g}"/>' if albedo[0] == albedo[1] == albedo[2] else
              f'<rgb name="albedo" value="{albedo[0]:.9g}, {albedo[1]:.9g}, {albedo[2]:.9g}"/>')
    return (f'<emitter type="sunsky"><vector name="sun_direction" x="{d[0]:.9g}" y="{d[1]:.9g}" z="{d[2]:.9g}"/>'
            f'<float name="turbidity" value="{record["turbidity"]:.9g}"/>{albedo}'
            f'<float name="sky_scale" value="{record["sky_scale"]:.9g}"/>'
            f'<float name="sun_scale" value="{record["sun_scale"]:.9g}"/>'
            f'<float name="sun_aperture" value="{record["sun_aperture"]:.9g}"/>'
            f'<boolean name="complex_sun" value="{str(bool(record["complex_sun"])).lower()}"/>'
            f'<transform name="to_world"><matrix value="{matrix}"/></transform></emitter>')


def _phong_as_roughplastic(match) -> str:
    """The roughplastic that the harness's loader renders for a ``phong`` element."""
    body = match.group(1)
    exponent = re.search(r'name="exponent" value="([^"]+)"', body)
    alpha = math.sqrt(2.0 / (float(exponent.group(1)) + 2.0)) if exponent else math.sqrt(2.0 / 32.0)
    body = re.sub(r'\s*<float name="exponent"[^>]*/>', "", body)
    return (f'<bsdf type="roughplastic"{body}<float name="alpha" value="{alpha}"/>'
            '<string name="distribution" value="beckmann"/></bsdf>')


def mitsuba_scene(folder: Path, scene, args, tmp: Path):
    """Load a Mitsuba 0.6 scene into Mitsuba 3 with our path settings (its sun and sky as Mitsuba 3's ``sunsky``)."""
    import mitsuba as mi

    xml = (folder / "scene.xml").read_text()
    integrator = (f'<integrator type="path"><integer name="maxDepth" value="{args.max_depth}"/>'
                  f'<integer name="rrDepth" value="{args.rr_depth}"/></integrator>')
    xml = re.sub(r"<integrator.*?</integrator>", integrator, xml, flags=re.S)
    xml = re.sub(r'<default name="[^"]*" value="[^"]*"\s*/>\s*', "", xml)
    xml = re.sub(r'(<integer name="sampleCount" value=")[^"]*"', rf'\g<1>{args.spp}"', xml)
    xml = re.sub(r'<integer name="width" value="\d+"\s*/>', f'<integer name="width" value="{args.width}"/>', xml)
    xml = re.sub(r'<integer name="height" value="\d+"\s*/>', f'<integer name="height" value="{args.height}"/>', xml)
    xml = xml.replace('"trilinear"', '"bilinear"')
    xml = xml.replace('<bsdf type="roughdiffuse"', '<bsdf type="diffuse"')
    xml = re.sub(r'<bsdf type="phong"(.*?)</bsdf>', _phong_as_roughplastic, xml, flags=re.S)
    record = scene.params.get("sunsky")
    lights = [_sunsky_xml(record)] if record is not None else []
    xml = re.sub(r"<emitter type=\"(sunsky|sun|sky)\".*?</emitter>", "".join(lights), xml, flags=re.S)
    mi.file_resolver().prepend(str(folder))
    for _ in range(50):  # Mitsuba 3 rejects parameters it does not use: drop them one by one
        try:
            return mi.load_string(xml)
        except RuntimeError as exc:
            names = re.findall(r'^\s*- \w+ "(\w+)"', str(exc), flags=re.M)
            if not names:
                raise
            for n in names:
                xml = re.sub(rf'\s*<\w+ name="({n}|{_camel(n)})"[^>]*/>', "", xml)
    raise RuntimeError("could not load the scene into Mitsuba 3")


def fastest_cpu_variant() -> tuple[str, str]:
    """(variant, why): ``llvm_ad_rgb`` where it renders here (its probe in a subprocess:
    ``plugins.renderers.mitsuba.variants``), else ``scalar_rgb`` and the reason."""
    from plugins.renderers.mitsuba.variants import VariantError, choose

    try:
        return choose("llvm"), "the fastest CPU variant"
    except VariantError as exc:
        return "scalar_rgb", str(exc).removeprefix("renderer 'mitsuba': ")


def mitsuba_variant(args) -> str:
    """The Mitsuba 3 variant of ``args.mitsuba_variant`` (``fastest``: :func:`fastest_cpu_variant`),
    printed once with the reason."""
    requested = getattr(args, "mitsuba_variant", "fastest")
    if requested != "fastest":
        args._variant = requested
        return requested
    if getattr(args, "_variant", None) is None:
        args._variant, why = fastest_cpu_variant()
        print(f"Mitsuba 3 variant: {args._variant} ({why})", flush=True)
    return args._variant


def mitsuba_frame(folder: Path, scene, args, tmp: Path, spp: int | None = None, seed: int = 0):
    """A function rendering one frame of the scene with Mitsuba 3 (:func:`mitsuba_variant`; an LLVM
    variant with Dr.Jit's threads set to Numba's count; returns the image); ``spp`` samples per
    pixel (default ``args.spp``)."""
    import mitsuba as mi

    mi.set_variant(mitsuba_variant(args))
    if mi.variant().startswith("llvm"):
        import drjit as dr

        dr.set_thread_count(numba.get_num_threads())
    mscene = mitsuba_scene(folder, scene, args, tmp)
    spp = spp or args.spp
    return lambda: np.asarray(mi.render(mscene, spp=spp, seed=seed), np.float64)[..., :3]


def relmse(image: np.ndarray, reference: np.ndarray) -> float:
    """``mean((x - r)^2 / (r^2 + 0.01))`` over pixels and channels (the harness's ``relmse``, uncorrected)."""
    x, r = np.asarray(image, np.float64), np.asarray(reference, np.float64)
    return float(np.mean((x - r) ** 2 / (r * r + 0.01)))


def region_means(image: np.ndarray, grid: int = 4) -> np.ndarray:
    """Mean of each region of a grid x grid partition (RGB averaged); rows and columns split evenly."""
    h, w = image.shape[:2]
    rows = np.array_split(np.arange(h), grid)
    cols = np.array_split(np.arange(w), grid)
    return np.array([[image[np.ix_(r, c)].mean() for c in cols] for r in rows])


def ratios(registry, args, old=None) -> None:
    """Region-mean ratios harness / Mitsuba 3 of converged images (see the module docstring);
    ``old``: :func:`baseline`'s (path tracer, loader) too."""
    from plugins.renderers.pathtracer import PathTracer

    size = (args.width, args.height)
    print(f"{args.width}x{args.height}, {args.spp} spp (Mitsuba 3: {args.mitsuba_spp or args.spp}), max_depth "
          f"{args.max_depth}; 4x4 regions, harness / Mitsuba 3")
    for name in args.scenes:
        folder = SCENES / name
        scene = harness_scene(registry, name)
        if scene is None or not (folder / "scene.xml").is_file():
            print(f"skipping {name!r}: no scene folder {folder}")
            continue
        images = {"": PathTracer(max_depth=args.max_depth, rr_depth=args.rr_depth).reference(scene, 0, spp=args.spp,
                                                                                            resolution=size)}
        if args.relmse:
            images[" (pixel centres)"] = PathTracer(max_depth=args.max_depth, rr_depth=args.rr_depth,
                                                    reference_pixel="centre").reference(scene, 0, spp=args.spp,
                                                                                        resolution=size)
        if old is not None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                old_scene = old[1](folder)
            images[" (baseline)"] = old[0](max_depth=args.max_depth, rr_depth=args.rr_depth).reference(
                old_scene, 0, spp=args.spp, resolution=size)
        with tempfile.TemporaryDirectory() as tmp:
            theirs = mitsuba_frame(folder, scene, args, Path(tmp), args.mitsuba_spp)()
            again = mitsuba_frame(folder, scene, args, Path(tmp), args.mitsuba_spp, seed=1)() if args.relmse else None
        for label, ours in images.items():
            r = region_means(ours.astype(np.float64)) / np.maximum(region_means(theirs), 1e-12)
            whole = ours.mean(axis=(0, 1)) / np.maximum(theirs.mean(axis=(0, 1)), 1e-12)
            print(f"{name + label:<12} median {np.median(r):.3f}  min {r.min():.3f}  max {r.max():.3f}  "
                  f"whole image (r, g, b) {whole[0]:.3f} {whole[1]:.3f} {whole[2]:.3f}", flush=True)
            print("  regions (rows top to bottom):", "; ".join(" ".join(f"{v:.2f}" for v in row) for row in r))
        if again is not None:
            floor = relmse(again, theirs)
            print(f"{name}: relMSE against Mitsuba 3 (seed 0): Mitsuba 3 seed 1 {floor:.4g} (its seed-to-seed noise)"
                  + "".join(f"; harness{label} {relmse(ours, theirs):.4g} ({relmse(ours, theirs) / floor:.2f}x)"
                            for label, ours in images.items()), flush=True)


def report(rows: list[dict], args) -> None:
    paths = args.width * args.height * args.spp
    threads = args.threads or numba.get_num_threads()
    variant = f", Mitsuba 3 {args._variant}" if getattr(args, "_variant", None) else ""
    print(f"\n{args.width}x{args.height}, {args.spp} spp, max_depth {args.max_depth}, rr_depth {args.rr_depth}, "
          f"{os.cpu_count()} CPUs, {threads} Numba threads{variant}; median [min-max] of {args.repeats}; "
          f"load average {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    print(f"{'renderer':<12} {'scene':<11} {'ms/frame':>22} {'Mpaths/s':>9} {'CPU ms':>9} {'Mpaths/CPU-s':>13}")
    for r in rows:
        wall, cpu = statistics.median(r["wall"]), statistics.median(r["cpu"])
        spread = f"{wall:.0f} [{min(r['wall']):.0f}-{max(r['wall']):.0f}]"
        print(f"{r['renderer']:<12} {r['scene']:<11} {spread:>22} {paths / wall / 1e3:>9.3f} {cpu:>9.1f} "
              f"{paths / cpu / 1e3:>13.3f}")
    for r in rows:
        if r["renderer"] != "baseline":
            continue
        for mine in (x for x in rows if x["scene"] == r["scene"] and x["renderer"].startswith("pathtracer")):
            for clock in ("wall", "cpu"):
                per = np.asarray(mine[clock]) / np.asarray(r[clock])
                print(f"{mine['renderer']} / baseline time per frame on {r['scene']} ({clock}, per frame pair): "
                      f"median {np.median(per):.3f}, range {per.min():.3f}-{per.max():.3f}")
    for r in rows:
        if r["renderer"] != "mitsuba3":
            continue
        for mine in (x for x in rows if x["scene"] == r["scene"] and x["renderer"] != "mitsuba3"):
            per = [m / o for m, o in zip(r["wall"], mine["wall"])]
            per_cpu = [m / o for m, o in zip(r["cpu"], mine["cpu"])]
            print(f"{mine['renderer']} / mitsuba3 paths per second on {r['scene']}: "
                  f"{statistics.median(r['wall']) / statistics.median(mine['wall']):.2f} (wall; frame pairs "
                  f"{min(per):.2f}-{max(per):.2f}), "
                  f"{statistics.median(r['cpu']) / statistics.median(mine['cpu']):.2f} (CPU time; "
                  f"{min(per_cpu):.2f}-{max(per_cpu):.2f})")


def arguments(argv=None):
    """The command line's options (see the module docstring)."""
    ap = parser(__doc__)
    ap.add_argument("--width", type=integer(1), default=1280)
    ap.add_argument("--height", type=integer(1), default=720)
    ap.add_argument("--spp", type=integer(1), default=1)
    ap.add_argument("--max-depth", type=integer(1), default=5)
    ap.add_argument("--rr-depth", type=integer(1), default=5)
    ap.add_argument("--repeats", type=integer(1), default=3)
    ap.add_argument("--scenes", nargs="+", default=None)
    ap.add_argument("--no-mitsuba", action="store_true")
    ap.add_argument("--baseline", default=None, metavar="REV", help="git revision whose path tracer runs too")
    ap.add_argument("--ratios", action="store_true", help="region-mean ratios to Mitsuba 3 instead of timings")
    ap.add_argument("--mitsuba-spp", type=integer(1), default=None,
                    help="with --ratios: Mitsuba 3's samples per pixel (default --spp)")
    ap.add_argument("--relmse", action="store_true",
                    help="with --ratios: also relMSE against Mitsuba 3's seed-0 image of the harness's pixel-area "
                         "and pixel-centre references and of Mitsuba 3's seed-1 image (its seed-to-seed noise)")
    ap.add_argument("--mitsuba-variant", default="fastest",
                    help="Mitsuba 3 variant; fastest (default): llvm_ad_rgb where it works (it needs "
                         "DRJIT_LIBLLVM_PATH naming a working libLLVM), else scalar_rgb")
    ap.add_argument("--threads", type=integer(1, numba.config.NUMBA_NUM_THREADS), nargs="+", default=None,
                    help="time our path tracer with each of these Numba thread counts")
    return ap.parse_args(argv)


def main(argv=None) -> int:
    args = arguments(argv)
    registry = load_plugins()
    with baseline(args.baseline) if args.baseline is not None else nullcontext() as old:
        if args.ratios:
            args.scenes = args.scenes or ["classroom", "living-room", "sponza"]
            ratios(registry, args, old)
        else:
            report(timings(registry, args, old), args)
    return 0


def timings(registry, args, old) -> list[dict]:
    """Every renderer's frames on every scene, taking turns frame by frame."""
    from plugins.renderers.pathtracer import PathTracer

    rows = []
    for name in args.scenes or ["atrium", "classroom"]:
        scene = harness_scene(registry, name)
        if scene is None:
            print(f"skipping {name!r}: neither a registered scene nor a folder {SCENES / name}")
            continue
        print(f"{name}: {len(scene.triangles(0).material)} triangles", flush=True)
        with tempfile.TemporaryDirectory() as tmp:
            folder = SCENES / name
            fns = {}
            if old is not None:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    old_scene = old[1](folder) if (folder / "scene.xml").is_file() else scene
                fns["baseline"] = frame_of(old[0], old_scene, args)
            if args.threads:
                for n in args.threads:
                    fns[f"pathtracer/{n}t"] = frame_of(PathTracer, scene, args, n)
            else:
                fns["pathtracer"] = frame_of(PathTracer, scene, args)
            if not args.no_mitsuba and (folder / "scene.xml").is_file():
                fns["mitsuba3"] = mitsuba_frame(folder, scene, args, Path(tmp))
            result = alternate(fns, args.repeats)
            for label in fns:
                rows.append({"renderer": label, "scene": name, "wall": result.ms[label], "cpu": result.cpu_ms[label]})
    return rows


if __name__ == "__main__":
    run(main)
