"""``denoise-bench export``: a scene's frames, G-buffer and references as a capture folder.

The folder is what the ``captured`` renderer reads (multi-layer OpenEXR per frame, references,
a ``capture.json`` sidecar written by :func:`harness.exr.write_capture`), so an exported scene
and the built-in one give the same frames and references bit for bit.
"""

from __future__ import annotations

from pathlib import Path

from harness.exr import write_capture
from harness.plan import choose_renderer
from harness.references import reference_record
from harness.renders import RenderStore


def export_scene(registry, store: RenderStore, spec, folder: str | Path, *, task: str = "denoise",
                 renderer: str | None = None, frames: int | None = None, spp: int = 1, seed: int = 0,
                 reference_spp: int | None = None, half: bool = False) -> Path:
    """Render (through the cache) and write one scene as a capture folder.

    Parameters
    ----------
    registry : harness.Registry
    store : RenderStore
    spec : SceneSpec
    folder : path
        The capture folder (created).
    task : str
        Whose renderer and references (``denoise`` or ``antialias``).
    renderer : str, optional
        Default: the scene's preferred renderer for the task.
    frames : int, optional
        At most this many frames.
    spp, seed : int
        Of the noisy frames.
    reference_spp : int, optional
        Default: the renderer's.
    half : bool
        Store half floats.

    Returns
    -------
    Path
        The sidecar's path.
    """
    rname = renderer or choose_renderer(registry, spec, task)
    if rname is None:
        raise ValueError(f"no renderer serves task {task!r} for scene {spec.name!r} ({spec.kind})")
    rspec = registry.get("renderer", rname)
    channels = rspec.provides if spec.channels is None else rspec.provides & spec.channels
    count = spec.frames if frames is None else min(spec.frames, frames)
    ref_spp = reference_spp if reference_spp is not None else rspec.reference_spp
    scene = store.scene(spec.name)
    rendered = [store.frame(scene, rname, t, spp=spp, seed=seed, channels=channels) for t in range(count)]
    records = ([reference_record(store, scene, rname, t, spp=ref_spp) for t in range(count)]
               if rspec.references else None)
    refs = [r.image for r in records] if records else None
    variances = [r.variance for r in records] if records else None
    return write_capture(folder, rendered, refs, name=spec.name, spp=spp, reference_spp=ref_spp,
                         reference_variances=variances, tags=sorted(spec.tags), tasks=sorted(spec.tasks), half=half)
