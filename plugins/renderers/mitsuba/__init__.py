"""The ``mitsuba`` renderer plugin: Mitsuba 3 renders the scenes loaded from Mitsuba XML, live.

Noisy frames, the G-buffer of the same first hits, variance channels and chunked references with
Mitsuba 3's ``path`` integrator, vectorized with its ``llvm_ad_rgb`` (CPU) or ``cuda_ad_rgb`` (GPU)
variant, ``scalar_rgb`` where neither works. Needs the ``mitsuba`` extra
(``pip install -e ".[mitsuba]"``); listed as broken where Mitsuba is missing. See
``docs/mitsuba.md``.
"""

import importlib.util

from harness import RendererSpec, hookimpl

if importlib.util.find_spec("mitsuba") is None:
    raise ImportError("the mitsuba renderer needs Mitsuba 3 (pip install 'denoise-harness[mitsuba]')")

from .renderer import GBUFFER_CHANNELS, MitsubaRenderer  # noqa: E402

VERSION = "1.0"
REFERENCE_SPP = 256


@hookimpl
def register_renderers():
    return [
        RendererSpec(
            name="mitsuba",
            version=VERSION,
            factory=MitsubaRenderer,
            provides=frozenset({"color", "variance", "spp", *GBUFFER_CHANNELS}),
            references=True,
            adaptive=True,
            scene_kinds=frozenset({"mesh"}),
            scene_tiers=frozenset({"real"}),  # the Mitsuba XML scenes, not the built-in meshes
            reference_spp=REFERENCE_SPP,
            chunked=True,
            tasks={"denoise"},
            description="Mitsuba 3 path integrator on Mitsuba XML scenes (llvm_ad_rgb CPU / cuda_ad_rgb GPU, "
                        "scalar_rgb fallback), pixel-centre G-buffer",
        )
    ]
