"""Capture a Blender (Cycles) animation as a folder the harness's ``captured`` renderer reads.

Usage, with Blender's executable or with the ``bpy`` module (``pip install bpy``)::

    blender -b scene.blend -P examples/capture/blender_capture.py -- OUT_DIR --spp 1 --reference-spp 1024
    python examples/capture/blender_capture.py OUT_DIR --blend scene.blend --spp 1 --reference-spp 1024
    python examples/capture/blender_capture.py OUT_DIR --demo --width 64 --height 36   # a built-in test scene

It renders the scene's frame range twice with Cycles: at ``--spp`` samples with the passes
Combined, Denoising Albedo, Normal, Depth, Position, Vector and Emission (multi-layer OpenEXR,
32-bit float, box pixel filter so one pixel holds only its own samples), then the Combined pass
at ``--reference-spp``. It writes ``capture.toml`` (preset ``blender``) with each frame's
world-to-clip matrices (OpenGL convention, as the harness's ``FrameMeta.view_proj``). The
noise seed changes per frame. Motion blur is switched off: the Vector pass needs it off.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def setup_passes(scene, spp: int) -> None:
    """Cycles at ``spp`` samples, no denoiser or motion blur, the passes the harness reads."""
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = spp
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.use_animated_seed = True
    scene.cycles.pixel_filter_type = "BOX"
    scene.render.use_motion_blur = False
    layer = scene.view_layers[0]
    layer.use_pass_z = layer.use_pass_normal = layer.use_pass_vector = True
    layer.use_pass_position = layer.use_pass_emit = True
    layer.cycles.denoising_store_passes = True
    settings = scene.render.image_settings
    if hasattr(settings, "media_type"):  # Blender 5
        settings.media_type = "MULTI_LAYER_IMAGE"
    settings.file_format = "OPEN_EXR_MULTILAYER"
    settings.color_depth = "32"
    settings.exr_codec = "ZIP"


def demo_scene(bpy, width: int, height: int) -> None:
    """A ground plane, a cube and a camera that moves sideways and rises over frames 1-3."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_plane_add(size=40, location=(0, 0, 0))
    bpy.ops.mesh.primitive_cube_add(size=1.5, location=(0.5, 1.0, 0.75))
    bpy.ops.object.light_add(type="SUN", location=(0, 0, 5))
    bpy.context.object.data.energy = 3.0
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(camera)
    scene.camera = camera
    camera.rotation_euler = (1.1, 0.0, 0.0)
    for frame, (x, z) in enumerate([(0.0, 3.0), (0.4, 3.1), (0.8, 3.25)], start=1):
        camera.location = (x, -6.0, z)
        camera.keyframe_insert("location", frame=frame)
    scene.frame_start, scene.frame_end = 1, 3
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100


def view_projections(bpy, scene) -> list:
    """World-to-clip matrix (OpenGL convention) of each frame of the range, as nested lists."""
    width, height = scene.render.resolution_x, scene.render.resolution_y
    out = []
    for frame in range(scene.frame_start, scene.frame_end + 1):
        scene.frame_set(frame)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        camera = scene.camera.evaluated_get(depsgraph)
        projection = camera.calc_matrix_camera(depsgraph, x=width, y=height)
        view_proj = projection @ camera.matrix_world.inverted()
        out.append([list(row) for row in view_proj])
    return out


def render_range(bpy, scene, pattern: str) -> None:
    scene.render.filepath = pattern
    bpy.ops.render.render(animation=True)


def sidecar(scene, spp: int, reference_spp: int, matrices: list, name: str) -> str:
    frames = scene.frame_end - scene.frame_start + 1
    entries = []
    for t, view_proj in enumerate(matrices):
        previous = matrices[t - 1] if t > 0 else view_proj
        entries.append(f"[[frame]]\nview_proj = {json.dumps(view_proj)}\nprev_view_proj = {json.dumps(previous)}\n"
                       f"camera_cut = {'true' if t == 0 else 'false'}\n")
    return f'''# written by examples/capture/blender_capture.py
name = "{name}"
description = "Blender Cycles, {spp} spp, box pixel filter"
preset = "blender"
frames = {frames}
first_frame = {scene.frame_start}
file = "frames/{{frame:04d}}.exr"
spp = {spp}

[reference]
file = "reference/{{frame:04d}}.exr"
layer = "{scene.view_layers[0].name}.Combined"
spp = {reference_spp}

''' + "\n".join(entries)


def main(argv=None) -> None:
    if argv is None:
        argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out_dir", type=Path)
    parser.add_argument("--blend", type=Path, help="the .blend file (default: the one Blender opened)")
    parser.add_argument("--demo", action="store_true", help="render a small built-in moving-camera scene")
    parser.add_argument("--width", type=int, help="override the render width (pixels)")
    parser.add_argument("--height", type=int, help="override the render height (pixels)")
    parser.add_argument("--spp", type=int, default=1)
    parser.add_argument("--reference-spp", type=int, default=1024)
    args = parser.parse_args(argv)

    import bpy

    if args.blend:
        bpy.ops.wm.open_mainfile(filepath=str(args.blend))
    if args.demo:
        demo_scene(bpy, args.width or 64, args.height or 36)
    scene = bpy.context.scene
    if args.width and args.height:
        scene.render.resolution_x, scene.render.resolution_y = args.width, args.height
        scene.render.resolution_percentage = 100
    if scene.view_layers[0].name != "ViewLayer":
        print(f"note: view layer {scene.view_layers[0].name!r}: edit the layer names of capture.toml's preset")
    out = args.out_dir.resolve()
    setup_passes(scene, args.spp)
    matrices = view_projections(bpy, scene)
    render_range(bpy, scene, str(out / "frames" / "####"))
    scene.cycles.samples = args.reference_spp
    render_range(bpy, scene, str(out / "reference" / "####"))
    name = args.blend.stem if args.blend else ("blender-demo" if args.demo else "blender-capture")
    (out / "capture.toml").write_text(sidecar(scene, args.spp, args.reference_spp, matrices, name))
    print(f"capture written to {out}")


if __name__ == "__main__":
    main()
