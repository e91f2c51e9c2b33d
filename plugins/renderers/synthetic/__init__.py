"""The ``synthetic`` renderer plugin: analytic frames for fast, exact filter tests."""

from harness import CHANNELS, RendererSpec, hookimpl

from .renderer import SyntheticRenderer

VERSION = "1.0"


@hookimpl
def register_renderers():
    return [
        RendererSpec(
            name="synthetic",
            version=VERSION,
            factory=SyntheticRenderer,
            provides=frozenset(CHANNELS),
            references=True,
            adaptive=True,
            scene_kinds=frozenset({"procedural"}),
            reference_spp=0,
            chunked=True,
            tasks={"denoise"},
            description="analytic G-buffer + exponential per-sample noise of known variance; exact references",
        )
    ]
