"""Built-in procedural mesh scenes: the embedded default suite.

``cornell``, ``atrium``, ``courtyard``, ``street`` and ``furnace`` are built with PyVista from
code alone (procedural textures, no asset files). Each builder runs in well under a few seconds
(a fresh :class:`harness.Scene` per call, so callers may not share mutable state).

The first four are sequences with moving objects and shadows and form the default suite.
``furnace`` (a validation scene with an analytic answer) is not in it: every one of its pixels
sees an emitter, and the error metrics leave emitter pixels out by default, so it has nothing
to score there; run it by name (with ``--emitters include``).
"""

from __future__ import annotations

from harness import SceneSpec, hookimpl

from . import atrium, cornell, courtyard, furnace, street

VERSION = "2.0"  # 2.0: sequences (atrium, courtyard 32 frames; cornell 8)


def _spec(module, description: str, suite: bool = True) -> SceneSpec:
    meta = module.SPEC  # the same constants the builder puts in its Scene
    return SceneSpec(
        name=meta["name"],
        version=VERSION,
        factory=module.build,
        tags=meta["tags"],
        frames=meta["frames"],
        resolution=meta["resolution"],
        kind="mesh",
        suite=suite,
        description=description,
    )


@hookimpl
def register_scenes():
    return [
        _spec(cornell, "Cornell box with an area light: soft shadows, colour bleeding"),
        _spec(atrium, "Sponza-like two-storey arcades, open roof, sun: hard shadows, strong indirect, "
                      "cloth banners, thin leaves"),
        _spec(courtyard, "San-Miguel-like courtyard: dense foliage, tables and chairs, glossy floor, "
                         "many small objects"),
        _spec(street, "Dynamic street: moving camera and car, glossy paint, disocclusions, emissive signs"),
        _spec(furnace, "White furnace: radiance Le/(1-rho) everywhere (analytic validation)", suite=False),
    ]
