"""``aa-fence``: a chain-link fence before shop signs of small text, a passing van, glossy shapes.

The camera dollies towards a chain-link fence (diagonal wires 1.2 cm thick on a 12 cm mesh:
about a pixel at the start, moire everywhere) behind which a wall carries signs of text-like
glyphs at three sizes and warning stripes. A white van with a glossy body and dark windows drives
between the fence and the wall (disocclusions behind the fence), and a chrome sphere and a
glossy cylinder turn in front of the fence (curved highlights). Boards with thin gaps pave the
ground. 24 frames.
"""

from __future__ import annotations

import numpy as np

from harness import Material, SceneObject, rotation, translation

from . import textures
from .daylight import camera_path, sky, suite_scene, sun
from .geometry import box, join, polydata, quad, sphere, tube

FRAMES = 24
SPEC = {
    "name": "aa-fence",
    "tags": frozenset({"antialias", "dynamic", "thin", "texture", "specular", "sun", "sky", "disocclusion"}),
    "frames": FRAMES,
    "resolution": (320, 180),
}

GROUND, WALL, SIGN_SMALL, SIGN_LARGE, STRIPES, FENCE, POST, PAINT, GLASS, CHROME, TYRE = range(11)


def _materials() -> list[Material]:
    return [
        Material("boards", albedo=(1.0, 1.0, 1.0), texture=textures.planks(128, 8, seed=4)),
        Material("wall", albedo=(0.62, 0.6, 0.56)),
        Material("sign_small", albedo=(1.0, 1.0, 1.0), texture=textures.glyphs(256, 24, seed=21)),
        Material("sign_large", albedo=(1.0, 1.0, 1.0),
                 texture=textures.glyphs(128, 6, seed=22, ink=(0.6, 0.05, 0.04), paper=(0.92, 0.9, 0.85))),
        Material("stripes", albedo=(1.0, 1.0, 1.0), texture=textures.stripes(64, 8)),
        Material("fence", kind="conductor", specular=(0.7, 0.72, 0.75), roughness=0.25),
        Material("post", kind="conductor", specular=(0.5, 0.5, 0.52), roughness=0.3),
        Material("van_paint", kind="plastic", albedo=(0.8, 0.82, 0.85), roughness=0.06),
        Material("van_glass", kind="conductor", specular=(0.06, 0.06, 0.07), roughness=0.03),
        Material("chrome", kind="conductor", specular=(0.9, 0.9, 0.9), roughness=0.07),
        Material("tyre", albedo=(0.03, 0.03, 0.03)),
    ]


def _fence() -> list:
    """Diagonal wires (both directions) on a 12 cm mesh between posts, x in [-6, 6], y in [0, 2]."""
    parts = []
    z = -1.0
    step = 0.12
    for c in np.arange(-8.0, 8.0, step):
        for direction in (1.0, -1.0):
            # the wire y = direction (x - c), clipped to the fence rectangle
            x0, x1 = c, c + direction * 2.0
            lo, hi = min(x0, x1), max(x0, x1)
            lo_c, hi_c = max(lo, -6.0), min(hi, 6.0)
            if hi_c - lo_c < 1e-3:
                continue
            ya, yb = direction * (lo_c - c), direction * (hi_c - c)
            parts.append(tube((lo_c, ya, z), (hi_c, yb, z), 0.006, FENCE, segments=4))
    for x in np.arange(-6.0, 6.01, 3.0):
        parts.append(tube((x, 0.0, z - 0.05), (x, 2.1, z - 0.05), 0.04, POST, segments=10))
    parts.append(tube((-6.0, 2.05, z - 0.05), (6.0, 2.05, z - 0.05), 0.025, POST, segments=10))
    return parts


def _wall() -> list:
    z = -7.0
    return [
        box((-12.0, 0.0, z - 0.5), (12.0, 6.0, z), WALL),
        quad((-7.0, 3.2, z + 0.01), (5.0, 0.0, 0.0), (0.0, 1.6, 0.0), SIGN_LARGE, uv_scale=(2.0, 0.5)),
        quad((-1.0, 1.0, z + 0.01), (3.0, 0.0, 0.0), (0.0, 2.0, 0.0), SIGN_SMALL, uv_scale=(1.0, 1.0)),
        quad((2.6, 1.0, z + 0.01), (1.4, 0.0, 0.0), (0.0, 1.0, 0.0), SIGN_SMALL, uv_scale=(1.0, 1.0)),
        quad((2.6, 2.3, z + 0.01), (4.0, 0.0, 0.0), (0.0, 0.4, 0.0), STRIPES, uv_scale=(6.0, 0.6)),
        quad((-11.0, 0.0, z + 0.01), (3.0, 0.0, 0.0), (0.0, 0.5, 0.0), STRIPES, uv_scale=(4.5, 0.75)),
    ]


def _van() -> list:
    body = box((-1.9, 0.35, -0.85), (1.9, 1.9, 0.85), PAINT)
    glass = join([quad((1.91, 1.15, -0.75), (0.0, 0.0, 1.5), (0.0, 0.65, 0.0), GLASS),
                  quad((-1.5, 1.2, 0.86), (2.6, 0.0, 0.0), (0.0, 0.55, 0.0), GLASS)])
    wheels = [tube((x, 0.33, -0.9), (x, 0.33, 0.9), 0.33, TYRE, segments=14) for x in (-1.25, 1.25)]
    return [body, glass] + wheels


def build():
    """Build the ``aa-fence`` scene."""
    s = np.linspace(0.0, 1.0, FRAMES)
    ground = quad((-30.0, 0.0, 30.0), (60.0, 0.0, 0.0), (0.0, 0.0, -60.0), GROUND, uv_scale=(30.0, 30.0))
    van_t = np.stack([translation((-9.0 + 14.0 * t, 0.0, -4.2)) for t in s])
    chrome_t = np.stack([translation((-1.6, 0.7, 1.2)) @ rotation((0, 1, 0), 25.0 * k) for k in range(FRAMES)])
    cylinder_t = np.stack([translation((1.8, 0.0, 1.6)) @ rotation((0, 1, 0), -20.0 * k) for k in range(FRAMES)])
    glossy_cylinder = join([tube((0.0, 0.0, 0.0), (0.0, 1.3, 0.0), 0.22, PAINT, segments=32),
                            tube((0.0, 1.3, 0.0), (0.0, 1.32, 0.0), 0.22, STRIPES, segments=32)])
    objects = [
        SceneObject("ground", polydata(ground)),
        SceneObject("wall", polydata(_wall())),
        SceneObject("fence", polydata(_fence())),
        SceneObject("van", polydata(_van()), transforms=van_t),
        SceneObject("chrome_ball", polydata(sphere(0.45, CHROME)), transforms=chrome_t),
        SceneObject("glossy_cylinder", polydata(glossy_cylinder), transforms=cylinder_t),
    ]
    eyes = np.stack([0.6 - 1.2 * s, 1.5 - 0.1 * s, 7.0 - 2.5 * s], 1)
    targets = np.stack([0.2 - 0.4 * s, np.full(FRAMES, 1.4), np.full(FRAMES, -7.0)], 1)
    return suite_scene(SPEC, objects=objects, materials=_materials(),
                       sun=sun((0.35, 0.6, 0.72), irradiance=2.2), environment=sky(),
                       camera=camera_path(eyes, targets, fov=55.0), max_depth=3)
