"""Capture a Mitsuba 3 scene as a folder the harness's ``captured`` renderer reads.

The ``mitsuba`` renderer plugin renders the scene (``docs/mitsuba.md``) and ``denoise-bench
export`` writes it, so a capture has what the plugin gives: motion vectors from the scene's camera
path and object poses, one object id per shape, the variance channel, and references with their
variance of the mean (for the harness's bias correction). This script is the command ::

    denoise-bench export --scene-dir SCENE_DIR --renderer mitsuba --out OUT_PARENT \\
        --resolution 160x90 --frames 4 --reference-spp 1024

with the renderer settings that the command line does not reach (``--max-depth``,
``--variance-spp``, ``--variant``), writing the capture into ``OUT_DIR`` itself, named
``<folder>-mitsuba3``. Usage::

    pip install -e ".[mitsuba]"      # llvm_ad_rgb needs a working libLLVM: see docs/mitsuba.md
    python examples/capture/mitsuba_capture.py SCENE_DIR OUT_DIR --width 160 --height 90 \\
        --frames 4 --reference-spp 1024

The number of frames is the scene's (at most ``--frames``): one for a Mitsuba file with a single
sensor and no animation sidecar. Renders go through the harness's cache (``--no-cache``: not).
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path


def main(argv=None) -> Path:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene_dir", type=Path, help="folder holding the Mitsuba scene XML")
    parser.add_argument("out_dir", type=Path, help="the capture folder to write")
    parser.add_argument("--width", type=int, default=160)
    parser.add_argument("--height", type=int, default=90)
    parser.add_argument("--frames", type=int, default=4, help="at most this many of the scene's frames")
    parser.add_argument("--spp", type=int, default=1, help="samples per pixel of the noisy frames")
    parser.add_argument("--seed", type=int, default=0, help="seed of the noisy frames")
    parser.add_argument("--reference-spp", type=int, default=1024)
    parser.add_argument("--variance-spp", type=int, default=8,
                        help="independent samples per pixel behind the variance channel of 1-spp frames")
    parser.add_argument("--max-depth", type=int, default=None, help="path length limit (default: the scene's)")
    parser.add_argument("--variant", default="auto", help="auto, llvm, cuda or scalar (default auto)")
    parser.add_argument("--no-cache", action="store_true", help="render everything again")
    args = parser.parse_args(argv)

    from harness import load_plugins
    from harness.cache import Cache
    from harness.export import export_scene
    from harness.renders import RenderStore
    from harness.specs import SceneSpec

    registry = load_plugins()
    settings = {"variant": args.variant, "max_depth": args.max_depth, "variance_spp": args.variance_spp}
    store = RenderStore(registry, Cache(enabled=not args.no_cache), resolution=(args.width, args.height),
                        renderer_settings={"mitsuba": settings})
    scene = registry.open_scene(args.scene_dir)
    scene = dataclasses.replace(scene, name=f"{args.scene_dir.resolve().name}-mitsuba3")
    store.add_scene(scene, path=args.scene_dir)
    spec = SceneSpec(name=scene.name, version="folder", factory=lambda: scene, tags=scene.tags,
                     frames=scene.frame_count, resolution=scene.resolution, kind=scene.kind, suite=False)
    sidecar = export_scene(registry, store, spec, args.out_dir, renderer="mitsuba", frames=args.frames, spp=args.spp,
                           seed=args.seed, reference_spp=args.reference_spp)
    print(f"capture written to {sidecar.parent} (open it with --scene-dir {sidecar.parent})")
    return sidecar


if __name__ == "__main__":
    main()
