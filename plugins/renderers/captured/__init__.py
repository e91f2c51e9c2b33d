"""The ``captured`` renderer plugin: frames from other renderers (OpenEXR AOVs) as scenes.

``open_scene(path)`` (``denoise-bench run --scene-dir PATH``) opens a folder holding a capture
sidecar (``capture.toml`` or ``capture.json``); the ``captured`` renderer serves its frames and
references. ``docs/captured.md`` describes the sidecar, the presets and the conventions.

A renderer spec declares its channels once for all scenes, so this one declares every channel;
each captured scene lists the channels it really has in ``scene.params["channels"]``.
"""

from harness import CHANNELS, RendererSpec, hookimpl

from .presets import PRESETS
from .reader import CaptureWarning
from .renderer import KIND, CapturedRenderer, open_capture
from .sidecar import Capture, CaptureError, load_sidecar

VERSION = "1.0"


@hookimpl
def register_renderers():
    return [
        RendererSpec(
            name="captured",
            version=VERSION,
            factory=CapturedRenderer,
            provides=frozenset(CHANNELS),
            references=True,
            adaptive=False,
            scene_kinds=frozenset({KIND}),
            reference_spp=0,
            reference_noise=True,
            deterministic=True,  # stored frames: every seed gives the same input
            tasks={"denoise"},
            description="frames, G-buffers and references captured by other renderers (OpenEXR AOVs + sidecar)",
        )
    ]


@hookimpl
def open_scene(path):
    return open_capture(path)


__all__ = ["PRESETS", "Capture", "CaptureError", "CaptureWarning", "CapturedRenderer", "load_sidecar", "open_capture"]
