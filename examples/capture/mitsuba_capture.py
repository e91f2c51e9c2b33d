"""Capture a Mitsuba 3 scene as a folder the harness's ``captured`` renderer reads.

Usage::

    pip install "denoise-harness[capture]"        # mitsuba >= 3.5
    python examples/capture/mitsuba_capture.py SCENE_DIR OUT_DIR --width 160 --height 90 \\
        --frames 4 --reference-spp 1024 --variance-renders 8

What it writes (see docs/captured.md)::

    OUT_DIR/capture.toml            sidecar: preset "mitsuba" plus the extra layers below
    OUT_DIR/frames/0000.exr         Mitsuba's own EXR of the ``aov`` integrator: the 1-spp
                                    ``path`` colour (layer ``color``) and the AOVs albedo,
                                    sh_normal (``normal``), depth and position
    OUT_DIR/extra/0000.exr          motion (zero: the camera is static), object_id (from
                                    pixel-centre rays) and, with --variance-renders K, the
                                    per-pixel sample variance of K more 1-spp renders
    OUT_DIR/reference/0000.exr      ``path`` at --reference-spp (one render: the scene and camera
                                    are static, so every frame shares it)

Frame ``t`` renders its noise with seed ``t``. Only the ``scalar_rgb`` variant is used. The scene
may be a Mitsuba 3 or 0.6 XML; parts Mitsuba 3 rejects are adapted (``roughdiffuse`` becomes
``diffuse``, trilinear/EWA texture filters become bilinear, unknown properties are dropped) and
each change is printed.
"""

from __future__ import annotations

import argparse
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

AOVS = "albedo:albedo,normal:sh_normal,depth:depth,position:position"


def load_scene(mi, folder: Path):
    """The Mitsuba scene of ``folder`` (``scene.xml``), its integrator removed, adapted to Mitsuba 3."""
    root = ET.parse(folder / "scene.xml").getroot()
    for node in root.findall("integrator"):
        root.remove(node)
    for bsdf in root.iter("bsdf"):
        if bsdf.get("type") == "roughdiffuse":
            print("note: roughdiffuse is not in Mitsuba 3; using diffuse")
            bsdf.set("type", "diffuse")
            for prop in [p for p in bsdf if p.get("name") in ("alpha", "distribution")]:
                bsdf.remove(prop)
    for texture in root.iter("texture"):
        for prop in texture:
            if prop.get("name") in ("filterType", "filter_type") and prop.get("value") not in ("nearest", "bilinear"):
                print(f"note: texture filter {prop.get('value')!r} is not in Mitsuba 3; using bilinear")
                prop.set("value", "bilinear")
    mi.file_resolver().prepend(str(folder))
    defaults = {"sampleCount": "1"}
    for _ in range(50):
        try:
            return mi.load_string(ET.tostring(root, encoding="unicode"), optimize=False, **defaults)
        except RuntimeError as exc:
            if not _drop_unreferenced(root, str(exc)):
                raise
    raise RuntimeError("could not adapt the scene for Mitsuba 3")


def _drop_unreferenced(root, message: str) -> bool:
    """Remove the properties an error names as unreferenced; True if any was removed."""
    plugin = re.search(r'in (\w+) plugin of type "(\w+)"', message)
    names = set(re.findall(r'- \w+ "(\w+)"', message))
    if not plugin or not names:
        return False
    tag, kind = plugin.groups()
    removed = 0
    for node in root.iter(tag):
        if node.get("type") != kind:
            continue
        for prop in list(node):
            name = prop.get("name") or ""
            if re.sub(r"(?<!^)(?=[A-Z])", "_", name).lower() in names:
                node.remove(prop)
                removed += 1
    if removed:
        print(f"note: dropped {sorted(names)} of {tag} {kind!r} (not used by Mitsuba 3)")
    return removed > 0


def make_sensor(mi, scene, width: int, height: int):
    """The scene's first camera at ``width`` x ``height`` with a box pixel filter (one sample = one pixel)."""
    original = scene.sensors()[0]
    params = mi.traverse(original)
    fov_x = float(params["x_fov"][0] if hasattr(params["x_fov"], "__len__") else params["x_fov"])
    sensor = mi.load_dict({
        "type": "perspective",
        "fov": fov_x,
        "fov_axis": "x",
        "to_world": original.world_transform(),
        "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"},
                 "pixel_format": "rgb"},
        "sampler": {"type": "independent", "sample_count": 1},
    })
    return sensor, fov_x


def object_ids(mi, scene, sensor, width: int, height: int) -> np.ndarray:
    """Index of the shape seen through each pixel centre, -1 for background, (H, W) int32."""
    index = {shape.id(): k for k, shape in enumerate(scene.shapes())}
    ids = np.full((height, width), -1, np.int32)
    for i in range(height):
        for j in range(width):
            ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f((j + 0.5) / width, (i + 0.5) / height), mi.Point2f(0.5))
            si = scene.ray_intersect(ray)
            if si.is_valid():
                ids[i, j] = index.get(si.shape.id(), -1)
    return ids


def render_color(mi, scene, sensor, spp: int, seed: int, max_depth: int) -> np.ndarray:
    """The ``path`` integrator's image at ``spp`` samples per pixel, (H, W, 3) float32."""
    path = mi.load_dict({"type": "path", "max_depth": max_depth})
    return np.asarray(mi.render(scene, sensor=sensor, integrator=path, spp=spp, seed=seed), np.float32)[..., :3]


def sidecar(name: str, frames: int, fov_x: float, spp: int, reference_spp: int, variance: bool, max_depth: int) -> str:
    extra = '\nvariance = { file = "extra/{frame:04d}.exr", layer = "variance" }' if variance else ""
    return f'''# written by examples/capture/mitsuba_capture.py
name = "{name}"
description = "Mitsuba 3 scalar_rgb: aov integrator + path (max_depth {max_depth}), static camera"
preset = "mitsuba"
frames = {frames}
spp = {spp}
tags = ["static", "mitsuba3"]

[reference]
file = "reference/{{frame:04d}}.exr"
layer = ""
spp = {reference_spp}

[channels]
motion = {{ file = "extra/{{frame:04d}}.exr", layer = "motion" }}
object_id = {{ file = "extra/{{frame:04d}}.exr", layer = "object_id" }}{extra}

[camera]
fov_x = {fov_x!r}
'''


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene_dir", type=Path, help="folder holding scene.xml")
    parser.add_argument("out_dir", type=Path)
    parser.add_argument("--width", type=int, default=160)
    parser.add_argument("--height", type=int, default=90)
    parser.add_argument("--frames", type=int, default=4)
    parser.add_argument("--reference-spp", type=int, default=1024)
    parser.add_argument("--variance-renders", type=int, default=0, metavar="K",
                        help="estimate the variance of the 1-spp colour from K more 1-spp renders (0: none)")
    parser.add_argument("--max-depth", type=int, default=8, help="path length limit of colour and reference")
    args = parser.parse_args(argv)

    import mitsuba as mi

    from harness import write_channels, write_exr

    mi.set_variant("scalar_rgb")
    scene = load_scene(mi, args.scene_dir)
    sensor, fov_x = make_sensor(mi, scene, args.width, args.height)
    aov = mi.load_dict({"type": "aov", "aovs": AOVS, "color": {"type": "path", "max_depth": args.max_depth}})
    ids = object_ids(mi, scene, sensor, args.width, args.height)
    zero = np.zeros((args.height, args.width), np.float32)
    out = args.out_dir
    (out / "frames").mkdir(parents=True, exist_ok=True)
    for t in range(args.frames):
        mi.render(scene, sensor=sensor, integrator=aov, spp=1, seed=t)
        sensor.film().bitmap().write(str(out / "frames" / f"{t:04d}.exr"))
        extra = {"motion.X": zero, "motion.Y": zero, "object_id.Y": ids.astype(np.float32)}
        k = args.variance_renders
        if k > 1:
            draws = np.stack([render_color(mi, scene, sensor, 1, 10_000 + t * k + n, args.max_depth) for n in range(k)])
            variance = draws.astype(np.float64).var(axis=0, ddof=1).astype(np.float32)
            extra.update({f"variance.{c}": variance[..., n] for n, c in enumerate("RGB")})
        write_channels(out / "extra" / f"{t:04d}.exr", extra)
        print(f"frame {t} written")
    reference = render_color(mi, scene, sensor, args.reference_spp, 1_000_000, args.max_depth)
    for t in range(args.frames):
        write_exr(out / "reference" / f"{t:04d}.exr", reference)
    name = f"{args.scene_dir.resolve().name}-mitsuba3"
    variance = args.variance_renders > 1
    text = sidecar(name, args.frames, fov_x, 1, args.reference_spp, variance, args.max_depth)
    (out / "capture.toml").write_text(text)
    print(f"capture written to {out}")


if __name__ == "__main__":
    main()
