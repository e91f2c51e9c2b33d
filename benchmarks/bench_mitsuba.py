"""The ``mitsuba`` renderer against the ``pathtracer`` on the shared Mitsuba scenes: agreement and speed.

Usage::

    python benchmarks/bench_mitsuba.py agree [--scenes classroom living-room sponza]
                                             [--width 160 --height 90 --spp 256 --seed 1]
    python benchmarks/bench_mitsuba.py speed [--scenes classroom living-room sponza] [--width 1280 --height 720]
                                             [--spp 1] [--rounds 3] [--workers 4 16]
                                             [--variant llvm_ad_rgb|cuda_ad_rgb|scalar_rgb]
                                             [--renderers pathtracer mitsuba]
    python benchmarks/bench_mitsuba.py sequence [--scenes living-room] [--frames 8] [--width 320 --height 180]
                                                [--export FOLDER] [--reference-spp 64]

``agree``: each scene as the Mitsuba scene plugin loads it, rendered by both renderers at the same
resolution, ``spp``, seed and path settings (the scene's ``max_depth``, Russian roulette from depth
5). First hits: the fraction of pixels where both see the same object, and there the largest
position difference (relative to the scene's size) and the fraction of equal normals, depths and
albedos. Radiance: the ratio mitsuba / pathtracer of the whole image's mean (r, g, b), and of the
mean over each object's pixels, for the objects whose two means are converged (both standard
errors, from the variance channels, below 1% of the mean): median, 5th and 95th percentiles, and
the share of pixels in objects within 2%. The loader's approximations (what the path tracer renders
differently from Mitsuba 3) are counted; they explain the outliers.

``speed``: frames of ``spp`` samples at ``width`` x ``height`` rendered by the renderers in turn
(two warm-up frames each, then ``rounds`` rounds alternating them, so all see the same machine
load), wall clock and process CPU time per frame (median), paths per second (wall), and the time
of a 4096-spp 1280x720 reference frame projected from it, alone and on ``--workers`` workers of
the same kind through Dask (references split into independent sample batches, so N workers
divide the time by about N; the cluster's overhead is not included). ``--variant`` is the
``mitsuba`` renderer's Mitsuba variant (``cuda_ad_rgb`` on a GPU machine; give it more ``--spp``
there, a 1-spp 1280x720 frame is too small to fill a GPU). Besides the table, each (scene,
renderer) prints one machine-readable line ``RESULT {json}`` with the scene, renderer, variant,
device, resolution, spp, rounds, seconds per frame (wall and CPU), paths per second (wall and
CPU) and the projected reference seconds (wall and CPU). On a loaded CPU the CPU-time figures are
the ones to compare (CPU-seconds divided by the idle cores give an idle machine's wall time); on
a GPU, the wall time. ``--scene-root`` names the folder of the scene folders; ``--bare``
(taken by itself where PyVista, which the scene plugin needs, is missing) reads each scene for
the ``mitsuba`` renderer alone (:func:`bare_scene`: its sensor as the camera, no triangles, so the
path tracer is not timed on it; a Mitsuba 0.6 sun/sky scene such as the classroom is skipped).
On a GPU machine without the project installed::

    pip install mitsuba     # with numpy, numba, pluggy, pyyaml, scipy, xxhash (harness's imports)
    python benchmarks/bench_mitsuba.py speed --variant cuda_ad_rgb --renderers mitsuba --spp 64 \
        --scene-root SCENES --scenes living-room sponza

``sequence``: the scene as a sequence, as the scene plugin loads it (the camera path and object
motion of its ``animation.toml``, else the generated default camera path; at most ``--frames``
frames), rendered by the ``mitsuba`` renderer, 1 spp: per frame, the number of distinct object ids,
the shapes of the file and the motion vectors' median and largest length. With ``--export
FOLDER`` the sequence is also written as a capture (``harness.export``) with references of
``--reference-spp``, which ``denoise-bench run --scene-dir FOLDER/<scene>-sequence`` scores with
every filter.

Both renderers use the machine's cores (Numba's thread count; Dr.Jit's thread pool is set to the
same). The third-party scenes are read from ``../shared/scenes`` next to the project root; a scene
that is absent is skipped with a message.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import subprocess
import warnings
from pathlib import Path

import numpy as np
from common import SHARED_SCENES, alternate, parser, run  # puts the project root on the path

SCENES = SHARED_SCENES
GBUFFER = ("position", "normal", "albedo", "depth", "object_id")
REFERENCE_SPP = 4096
REFERENCE_PIXELS = 1280 * 720


def shared_scene(name: str, root: Path = SCENES, bare: bool = False):
    """The scene of ``root/<name>`` as the Mitsuba scene plugin loads it, or None (with a message) where absent.

    ``bare`` (or a machine without PyVista, which the scene plugin needs): :func:`bare_scene`.
    """
    folder = Path(root) / name
    if not (folder / "scene.xml").is_file():
        print(f"skipping {name!r}: no scene folder {folder}")
        return None
    if not bare:
        try:
            from plugins.scenes.mitsuba import load
        except ImportError as exc:
            print(f"the Mitsuba scene plugin cannot be imported ({exc}): scenes for the mitsuba renderer alone")
            bare = True
    if bare:
        return bare_scene(folder, name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load(folder, name=name)


def bare_scene(folder: Path, name: str):
    """A harness scene of ``folder/scene.xml`` for the ``mitsuba`` renderer alone, without the scene plugin.

    The camera is the file's sensor as Mitsuba 3 reads it (its ``to_world`` and field of view); the
    scene has no objects (the path tracer cannot render it; every shape gets an object id of its
    own). A Mitsuba 0.6 sun/sky, which only the scene plugin turns into Mitsuba 3's ``sunsky``, is
    not rendered: such a scene returns None with a message.
    """
    import xml.etree.ElementTree as ET

    import mitsuba as mi

    from harness import CameraPath, Scene
    from plugins.renderers.mitsuba.variants import active

    path = folder / "scene.xml"
    root = ET.parse(path).getroot()
    if any(e.get("type") in ("sun", "sky", "sunsky") for e in root.findall("emitter")) and \
            root.get("version", "0.6.0").startswith("0."):
        print(f"skipping {name!r}: its Mitsuba 0.6 sun/sky needs the scene plugin (and PyVista)")
        return None
    sensor = root.find("sensor")
    if sensor is None:
        print(f"skipping {name!r}: no sensor in {path}")
        return None
    for child in sensor.findall("sampler") + sensor.findall("film"):
        sensor.remove(child)
    film = ET.SubElement(sensor, "film", type="hdrfilm")  # the size alone (0.6 films carry tone mapping)
    film.extend(n for n in root.iter("integer") if n.get("name") in ("width", "height"))
    only = ET.Element("scene", version=root.get("version", "0.6.0"))
    only.extend(root.findall("default") + [sensor])
    with active(mi, "scalar_rgb"):
        camera = mi.load_string(ET.tostring(only, encoding="unicode")).sensors()[0]
        params = mi.traverse(camera)
        matrix = np.array(params["to_world"].matrix, np.float64)
        width, height = (int(v) for v in camera.film().size())
        x_fov = float(params["x_fov"][0] if hasattr(params["x_fov"], "__len__") else params["x_fov"])
    eye, forward, up = matrix[:3, 3], matrix[:3, 2], matrix[:3, 1]
    fov = np.degrees(2.0 * np.arctan(np.tan(np.radians(x_fov) / 2.0) * height / width))
    return Scene(name=name, kind="mesh", resolution=(width, height), camera=CameraPath(
        positions=[eye], targets=[eye + forward], up=tuple(float(v) for v in up), fov=float(fov)),
        params={"format": "mitsuba", "file": path.name}, max_depth=5, source=str(folder))


def renderers():
    from plugins.renderers.mitsuba import MitsubaRenderer
    from plugins.renderers.pathtracer import PathTracer

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mitsuba = MitsubaRenderer()
    return {"pathtracer": PathTracer(), "mitsuba": mitsuba}


def agree(args) -> None:
    both = renderers()
    size = (args.width, args.height)
    print(f"{args.width}x{args.height}, {args.spp} spp, seed {args.seed}, mitsuba variant {both['mitsuba'].variant}; "
          "ratios mitsuba / pathtracer")
    for name in args.scenes:
        scene = shared_scene(name, args.scene_root)
        if scene is None:
            continue
        channels = set(GBUFFER) | {"variance"}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ours, theirs = (both[r].render(scene, 0, spp=args.spp, seed=args.seed, channels=channels,
                                           resolution=size) for r in ("mitsuba", "pathtracer"))
        print(f"{name}: {len(scene.params.get('approximations', []))} approximations of the path tracer's loader")
        gbuffer_line(scene, ours, theirs)
        radiance_lines(scene, ours, theirs)


def gbuffer_line(scene, ours, theirs) -> None:
    same = (ours["object_id"] == theirs["object_id"]) & (ours["object_id"] >= 0)
    hits = ((ours["object_id"] >= 0) == (theirs["object_id"] >= 0)).mean()
    points = np.concatenate([np.asarray(o.mesh.points) for o in scene.objects])
    size = float(np.linalg.norm(points.max(0) - points.min(0)))
    gap = np.linalg.norm(ours["position"][same] - theirs["position"][same], axis=-1) / size
    equal = {}
    for name in ("normal", "depth", "albedo"):
        difference = np.abs(ours[name][same] - theirs[name][same]).reshape(same.sum(), -1).max(-1)
        equal[name] = float(np.mean(difference <= 1e-3 * (size if name == "depth" else 1.0)))
    print(f"  first hits: hit/miss agree {hits:.4f}, same object {same.mean():.4f} of pixels; there: position "
          f"difference max {gap.max(initial=0):.2e} of the scene size, equal (1e-3) normal {equal['normal']:.4f} "
          f"depth {equal['depth']:.4f} albedo {equal['albedo']:.4f}")


def radiance_lines(scene, ours, theirs) -> None:
    whole = ours["color"].mean(axis=(0, 1)) / np.maximum(theirs["color"].mean(axis=(0, 1)), 1e-12)
    same = (ours["object_id"] == theirs["object_id"]) & (ours["object_id"] >= 0)
    ratios, weights = [], []
    for k in np.unique(ours["object_id"][same]):
        region = same & (ours["object_id"] == k)
        means = [f["color"][region].astype(np.float64).mean() for f in (ours, theirs)]
        errors = [np.sqrt(f["variance"][region].astype(np.float64).mean(-1).sum()) / region.sum()
                  for f in (ours, theirs)]
        if min(means) <= 0 or max(e / m for e, m in zip(errors, means)) > 0.01:
            continue
        ratios.append(means[0] / means[1])
        weights.append(int(region.sum()))
    ratios, weights = np.array(ratios), np.array(weights)
    within = float(weights[np.abs(ratios - 1) <= 0.02].sum() / max(weights.sum(), 1))
    print(f"  radiance: whole image (r, g, b) {whole[0]:.4f} {whole[1]:.4f} {whole[2]:.4f}; {len(ratios)} converged "
          f"objects ({weights.sum()} pixels): median {np.median(ratios) if len(ratios) else np.nan:.4f}, "
          f"5-95% {np.percentile(ratios, 5) if len(ratios) else np.nan:.4f}-"
          f"{np.percentile(ratios, 95) if len(ratios) else np.nan:.4f}, pixels in objects within 2%: {within:.3f}")


def renderer_list(names, variant: str):
    """The renderers to time, by name, the ``mitsuba`` one with ``variant``."""
    made = {}
    for name in names:
        if name == "pathtracer":
            from plugins.renderers.pathtracer import PathTracer

            made[name] = PathTracer()
        else:
            from plugins.renderers.mitsuba import MitsubaRenderer

            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                made[name] = MitsubaRenderer(variant=variant)
    return made


def device_name(variant: str) -> str:
    """The GPU (``nvidia-smi``) for a CUDA variant, else the CPU model and the cores used."""
    if variant.startswith("cuda"):
        try:
            done = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True,
                                  text=True, timeout=30)
            return done.stdout.strip().splitlines()[0]
        except (OSError, IndexError, subprocess.TimeoutExpired):
            return "a CUDA GPU"
    from harness import compute_threads

    model = platform.processor() or "CPU"
    try:
        model = next(line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                     if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return f"{model}, {compute_threads()} threads"


def speed(args) -> None:
    everyone = renderer_list(args.renderers, args.variant)
    size = (args.width, args.height)
    paths = args.width * args.height * args.spp
    names = {r: (f"mitsuba {renderer.variant}" if r == "mitsuba" else r) for r, renderer in everyone.items()}
    print(f"{args.width}x{args.height}, {args.spp} spp per frame, {args.rounds} rounds alternating "
          f"{', '.join(names.values())}; load average {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    for name in args.scenes:
        scene = shared_scene(name, args.scene_root, args.bare)
        if scene is None:
            continue
        timed = dict(everyone)
        if not scene.objects and timed.pop("pathtracer", None) is not None:
            print(f"{name}: the path tracer is not timed (a scene without the scene plugin has no triangles)")
        seeds = {r: iter(range(2, 2 + args.rounds + 1)) for r in timed}  # a new seed per timed frame
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for renderer in timed.values():  # warm-up (alternate() adds one): loading, BVH, compilation
                renderer.render(scene, 0, spp=args.spp, seed=0, resolution=size)
            result = alternate({r: (lambda renderer=renderer, scene=scene, seed=seeds[r]: renderer.render(
                scene, 0, spp=args.spp, seed=next(seed), resolution=size)) for r, renderer in timed.items()},
                args.rounds)
        times = {r: list(zip(np.divide(result.ms[r], 1e3), np.divide(result.cpu_ms[r], 1e3))) for r in timed}
        rates, cpu_rates = {}, {}
        for r, samples in times.items():
            wall = statistics.median(s[0] for s in samples)
            cpu = statistics.median(s[1] for s in samples)
            rates[r], cpu_rates[r] = paths / wall, paths / max(cpu, 1e-9)
            reference = REFERENCE_PIXELS * REFERENCE_SPP / rates[r]
            reference_cpu = REFERENCE_PIXELS * REFERENCE_SPP / cpu_rates[r]
            variant = getattr(timed[r], "variant", None)
            print(f"{name:<12} {names[r]:<24} {wall:8.3f} s wall {cpu:8.3f} s CPU per frame, {rates[r] / 1e6:7.3f} "
                  f"Mpaths/s, {cpu_rates[r] / 1e6:7.3f} Mpaths/CPU-s; a {REFERENCE_SPP}-spp 1280x720 reference "
                  f"frame: {reference / 3600:7.3f} h wall, {reference_cpu / 3600:7.3f} CPU-h")
            record = {"scene": name, "renderer": r, "variant": variant, "device": device_name(variant or "cpu"),
                      "width": args.width, "height": args.height, "spp": args.spp, "rounds": args.rounds,
                      "wall_s_per_frame": round(wall, 4), "cpu_s_per_frame": round(cpu, 4),
                      "paths_per_s": round(rates[r], 1), "paths_per_cpu_s": round(cpu_rates[r], 1),
                      "reference_s_1280x720_4096spp": round(reference, 1),
                      "reference_cpu_s_1280x720_4096spp": round(reference_cpu, 1),
                      "load_average": round(os.getloadavg()[0], 2)}
            print("RESULT " + json.dumps(record), flush=True)
        if "mitsuba" in rates and "pathtracer" in rates:
            print(f"{name:<12} mitsuba / pathtracer paths per second: {rates['mitsuba'] / rates['pathtracer']:.2f} "
                  f"(wall), {cpu_rates['mitsuba'] / cpu_rates['pathtracer']:.2f} (CPU)")
        for r, rate in rates.items():
            hours = REFERENCE_PIXELS * REFERENCE_SPP / rate / 3600
            spread = ", ".join(f"{n} workers {hours / n:.2f} h" for n in args.workers)
            print(f"  a 4096-spp 1280x720 reference frame of {name} by {names[r]}: {hours:.3f} h here; {spread}")


def sequence(args) -> None:
    import dataclasses

    from harness import load_plugins
    from harness.cache import Cache
    from harness.export import export_scene
    from harness.renders import RenderStore
    from harness.specs import SceneSpec

    mitsuba = renderers()["mitsuba"]
    size = (args.width, args.height)
    channels = {"albedo", "normal", "depth", "position", "object_id", "motion", "emission", "variance"}
    for name in args.scenes:
        scene = shared_scene(name, args.scene_root)
        if scene is None:
            continue
        scene = dataclasses.replace(scene, name=f"{name}-sequence", frame_count=min(scene.frame_count, args.frames),
                                    resolution=size)
        loaded = mitsuba.loaded(scene)
        shapes = len(loaded.engine.scene.shapes())
        print(f"{scene.name}: {scene.frame_count} frames at {args.width}x{args.height}, variant {mitsuba.variant}, "
              f"{shapes} shapes in the file, {len(scene.objects)} scene objects; {len(set(loaded.ids.values()))} "
              f"distinct object ids for the {len(loaded.ids)} shapes, {loaded.unmatched} shapes without an object")
        for t in range(scene.frame_count):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                frame = mitsuba.render(scene, t, spp=1, seed=0, channels=channels)
            hit = frame["object_id"] >= 0
            length = np.linalg.norm(frame["motion"], axis=-1)
            print(f"  frame {t}: {len(np.unique(frame['object_id'][hit]))} distinct object ids on {hit.mean():.2f} of "
                  f"the pixels, motion length median {np.median(length):.2f} max {length.max():.2f} px")
        if args.export is not None:
            registry = load_plugins()
            store = RenderStore(registry, Cache(), resolution=size)
            store.add_scene(scene)
            spec = SceneSpec(name=scene.name, version="sequence", factory=lambda s=scene: s, tags=scene.tags,
                             frames=scene.frame_count, resolution=size, kind="mesh", suite=False)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                sidecar = export_scene(registry, store, spec, args.export / scene.name, renderer="mitsuba",
                                       reference_spp=args.reference_spp)
            print(f"  written to {sidecar.parent}")


def main(argv=None) -> None:
    options = parser(__doc__)
    sub = options.add_subparsers(dest="what", required=True)
    a = sub.add_parser("agree")
    a.add_argument("--scenes", nargs="+", default=["classroom", "living-room", "sponza"])
    a.add_argument("--width", type=int, default=160)
    a.add_argument("--height", type=int, default=90)
    a.add_argument("--spp", type=int, default=256)
    a.add_argument("--seed", type=int, default=1)
    s = sub.add_parser("speed")
    s.add_argument("--scenes", nargs="+", default=["classroom", "living-room", "sponza"])
    s.add_argument("--bare", action="store_true",
                   help="scenes without the scene plugin (no PyVista needed): the mitsuba renderer alone")
    s.add_argument("--renderers", nargs="+", choices=["pathtracer", "mitsuba"], default=["pathtracer", "mitsuba"])
    s.add_argument("--variant", default="llvm_ad_rgb",
                   help="Mitsuba variant: llvm_ad_rgb, cuda_ad_rgb, scalar_rgb (or auto, llvm, cuda, scalar)")
    s.add_argument("--width", type=int, default=1280)
    s.add_argument("--height", type=int, default=720)
    s.add_argument("--spp", type=int, default=1)
    s.add_argument("--rounds", type=int, default=3)
    s.add_argument("--workers", type=int, nargs="+", default=[4, 16])
    q = sub.add_parser("sequence")
    q.add_argument("--scenes", nargs="+", default=["living-room"])
    q.add_argument("--frames", type=int, default=8)
    q.add_argument("--width", type=int, default=320)
    q.add_argument("--height", type=int, default=180)
    q.add_argument("--export", type=Path, default=None)
    q.add_argument("--reference-spp", type=int, default=64)
    for command in (a, s, q):
        command.add_argument("--scene-root", type=Path, default=SCENES,
                             help="folder holding the scene folders (default ../shared/scenes beside the project)")
    args = options.parse_args(argv)
    {"agree": agree, "speed": speed, "sequence": sequence}[args.what](args)


if __name__ == "__main__":
    run(main)
