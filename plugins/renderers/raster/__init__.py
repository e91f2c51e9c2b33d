"""The ``raster`` renderer plugin: PyVista/VTK off-screen G-buffers with exact float values.

VTK rasterizes a float visibility buffer (triangle index per pixel centre); positions, depth,
normals, uv and textured albedo are then computed in float64 from the primary rays, so they are
never 8-bit quantized and agree with a ray tracer's first hits. ``color`` is a cheap local
shading (no shadows), and ``reference()`` the same shading supersampled: see ``docs/raster.md``.
"""

from __future__ import annotations

from harness import RendererSpec, hookimpl

from .renderer import PROVIDES, RasterRenderer

VERSION = "1.2"


@hookimpl
def register_renderers():
    return [
        RendererSpec(
            name="raster",
            version=VERSION,
            factory=RasterRenderer,
            provides=PROVIDES,
            references=True,
            adaptive=False,
            deterministic=True,  # rasterization: every seed gives the same frames
            scene_kinds={"mesh"},
            reference_spp=64,
            tasks={"antialias"},
            description="PyVista/VTK rasterized float G-buffer, local shading; SSAA references",
        )
    ]
