"""The ``pathtracer`` renderer plugin: a Numba CPU path tracer of mesh scenes.

BVH (binned SAH) + watertight ray-triangle tests, Lambert / GGX conductor / GGX plastic / mirror /
dielectric materials, emissive triangles + sun + environment with next-event estimation and MIS,
counter-based random numbers (bit-identical for any thread count, resumable sample streams).
See ``docs/pathtracer.md``.
"""

from harness import CHANNELS, RendererSpec, hookimpl

from .pixel_sampling import BLOCK
from .renderer import PathTracer

VERSION = "1.0"
REFERENCE_SPP = 256


@hookimpl
def register_renderers():
    return [
        RendererSpec(
            name="pathtracer",
            version=VERSION,
            factory=PathTracer,
            provides=frozenset(CHANNELS),
            references=True,
            adaptive=True,
            scene_kinds=frozenset({"mesh"}),
            reference_spp=REFERENCE_SPP,
            chunked=True,
            sample_block=BLOCK,
            tasks={"denoise"},
            description="Numba CPU path tracer: SAH BVH, NEE + MIS, GGX materials, sun/sky/env lights",
        )
    ]
