"""Anti-aliasing scenes: what aliases in a game frame, animated, for the ``antialias`` task.

Every scene mixes geometric edges, thin geometry narrower than a pixel in places (railings,
wires, fences, grass), high-frequency textures without mip-maps (minified checkerboards,
text-like glyphs) and glossy curved surfaces whose small sun highlights alias in shading. Each
is a sequence of 24 frames with camera motion and at least one moving object (disocclusions),
built from code alone in well under a second. See ``docs/antialias.md``.
"""

from __future__ import annotations

from harness import SceneSpec, hookimpl

from . import fence, garden, railing

VERSION = "1.0"


def _spec(module, description: str) -> SceneSpec:
    meta = module.SPEC
    return SceneSpec(name=meta["name"], version=VERSION, factory=module.build, tags=meta["tags"],
                     frames=meta["frames"], resolution=meta["resolution"], kind="mesh", suite=True,
                     description=description, tasks={"antialias"})


@hookimpl
def register_scenes():
    return [
        _spec(railing, "terrace railing, minified checkered plaza, text billboard, power lines, rolling ball"),
        _spec(fence, "chain-link fence before text signs, passing van, turning chrome ball and glossy cylinder"),
        _spec(garden, "grass blades, swaying leafy shrub, picket fence, chrome gazing ball, rolling ball"),
    ]
