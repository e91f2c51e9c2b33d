"""Throughput of the ``pathtracer`` renderer, and of Mitsuba 3 on the same classroom scene.

Usage::

    python benchmarks/bench_pathtracer.py [--width 1280] [--height 720] [--spp 1] [--max-depth 5]
                                          [--repeats 3] [--scenes atrium classroom] [--no-mitsuba]

For each scene: paths per second and milliseconds per ``spp``-sample frame (median of
``repeats`` timed frames after one warm-up frame; wall clock, ``time.perf_counter_ns``, plus the
process CPU time, which is steadier on a shared machine). A timed frame is a complete render:
primary rays, first hits and the path samples (the BVH is built once per scene, during the
warm-up, as Mitsuba builds its own when loading). Then, in the same process, Mitsuba 3
(``scalar_rgb`` variant, ``path`` integrator, same resolution, spp, ``max_depth`` and Russian
roulette depth) renders ``../shared/scenes/classroom/scene.xml`` with the lights that the
harness's Mitsuba loader gives our renderer: the sun as a directional light of the same
irradiance and direction, the sky gradient as an environment map. The third-party scene folder
is found next to the project root and the benchmark skips it, with a message, when it is absent.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import statistics
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from harness import load_plugins

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT.parent / "shared" / "scenes"


def timed(fn, repeats: int) -> tuple[list[float], list[float]]:
    """Wall and CPU milliseconds of ``repeats`` calls after one warm-up call."""
    fn()
    wall, cpu = [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter_ns()
        fn()
        wall.append((time.perf_counter_ns() - t0) / 1e6)
        cpu.append((time.process_time() - c0) * 1e3)
    return wall, cpu


def harness_scene(registry, name: str):
    if name in registry.scenes:
        return registry.scenes[name].factory()
    folder = SCENES / name
    if folder.is_dir():
        return registry.open_scene(folder)
    return None


def bench_ours(scene, args) -> dict:
    from plugins.renderers.pathtracer import PathTracer

    renderer = PathTracer(max_depth=args.max_depth, rr_depth=args.rr_depth)
    size = (args.width, args.height)

    def frame():
        renderer._setups.clear()  # a complete frame: primary rays and first hits included
        renderer.render(scene, 0, spp=args.spp, seed=0, resolution=size)

    return dict(zip(("wall", "cpu"), timed(frame, args.repeats)))


def _camel(name: str) -> str:
    head, *rest = name.split("_")
    return head + "".join(p.title() for p in rest)


def _sky_map(env, path: Path, height: int = 64) -> None:
    """Write the sky gradient of a harness ``Environment`` as an equirectangular EXR."""
    import mitsuba as mi

    theta = (np.arange(height) + 0.5) / height * math.pi
    t = np.maximum(np.cos(theta), 0.0)[:, None]
    rgb = np.asarray(env.horizon)[None, :] + (np.asarray(env.radiance) - np.asarray(env.horizon))[None, :] * t
    img = np.repeat(rgb[:, None, :], 2 * height, axis=1).astype(np.float32)
    mi.Bitmap(img).write(str(path))


def mitsuba_scene(folder: Path, scene, args, tmp: Path):
    """Load a Mitsuba 0.6 scene into Mitsuba 3 with our path settings and the harness's lights."""
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
    lights = []
    if scene.sun is not None:
        solid = 2 * math.pi * (1 - math.cos(math.radians(scene.sun.angular_radius)))
        e = [v * solid for v in scene.sun.radiance]
        d = [-v for v in scene.sun.direction]
        lights.append(f'<emitter type="directional"><vector name="direction" x="{d[0]}" y="{d[1]}" z="{d[2]}"/>'
                      f'<rgb name="irradiance" value="{e[0]}, {e[1]}, {e[2]}"/></emitter>')
    if scene.environment is not None and scene.environment.kind in ("sky", "constant"):
        sky = tmp / "sky.exr"
        _sky_map(scene.environment, sky)
        lights.append(f'<emitter type="envmap"><string name="filename" value="{sky}"/></emitter>')
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


def bench_mitsuba(folder: Path, scene, args) -> dict:
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    with tempfile.TemporaryDirectory() as tmp:
        mscene = mitsuba_scene(folder, scene, args, Path(tmp))
        return dict(zip(("wall", "cpu"), timed(lambda: mi.render(mscene, spp=args.spp, seed=0), args.repeats)))


def report(rows: list[dict], args) -> None:
    paths = args.width * args.height * args.spp
    print(f"\n{args.width}x{args.height}, {args.spp} spp, max_depth {args.max_depth}, rr_depth {args.rr_depth}, "
          f"{os.cpu_count()} CPUs, {numba.get_num_threads()} Numba threads; median of {args.repeats}")
    print(f"{'renderer':<12} {'scene':<11} {'ms/frame':>10} {'Mpaths/s':>9} {'CPU ms':>9} {'Mpaths/CPU-s':>13}")
    for r in rows:
        wall, cpu = statistics.median(r["wall"]), statistics.median(r["cpu"])
        print(f"{r['renderer']:<12} {r['scene']:<11} {wall:>10.1f} {paths / wall / 1e3:>9.3f} {cpu:>9.1f} "
              f"{paths / cpu / 1e3:>13.3f}")
    ours = {r["scene"]: r for r in rows if r["renderer"] == "pathtracer"}
    for r in rows:
        if r["renderer"] == "mitsuba3" and r["scene"] in ours:
            mine = ours[r["scene"]]
            print(f"pathtracer / mitsuba3 paths per second on {r['scene']}: "
                  f"{statistics.median(r['wall']) / statistics.median(mine['wall']):.2f} (wall), "
                  f"{statistics.median(r['cpu']) / statistics.median(mine['cpu']):.2f} (CPU time)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=720)
    parser.add_argument("--spp", type=int, default=1)
    parser.add_argument("--max-depth", type=int, default=5)
    parser.add_argument("--rr-depth", type=int, default=5)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--scenes", nargs="+", default=["atrium", "classroom"])
    parser.add_argument("--no-mitsuba", action="store_true")
    args = parser.parse_args()
    registry = load_plugins()
    rows = []
    for name in args.scenes:
        scene = harness_scene(registry, name)
        if scene is None:
            print(f"skipping {name!r}: neither a registered scene nor a folder {SCENES / name}")
            continue
        print(f"{name}: {len(scene.triangles(0).material)} triangles", flush=True)
        rows.append({"renderer": "pathtracer", "scene": name, **bench_ours(scene, args)})
        folder = SCENES / name
        if not args.no_mitsuba and (folder / "scene.xml").is_file():
            rows.append({"renderer": "mitsuba3", "scene": name, **bench_mitsuba(folder, scene, args)})
    report(rows, args)


if __name__ == "__main__":
    main()
