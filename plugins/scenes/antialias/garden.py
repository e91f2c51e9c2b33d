"""``aa-garden``: grass, a leafy shrub swaying in the wind, a picket fence and glossy garden balls.

The camera circles a small garden: a lawn of about 2,500 thin grass blades, a shrub of twigs and
leaf blades that sways (a moving object whose thin parts uncover what lies behind them), a white
picket fence with a checkered tile path, a chrome gazing ball on a column (a sharp highlight on a
sphere) and a glossy blue ball rolling across the path. 24 frames.
"""

from __future__ import annotations

import numpy as np

from harness import Material, SceneObject, rotation, translation

from . import textures
from .daylight import camera_path, sky, suite_scene, sun
from .geometry import blade, box, join, polydata, quad, sphere, tube

FRAMES = 24
SPEC = {
    "name": "aa-garden",
    "tags": frozenset({"antialias", "dynamic", "foliage", "thin", "texture", "specular", "sun", "sky",
                       "disocclusion"}),
    "frames": FRAMES,
    "resolution": (320, 180),
}

SOIL, GRASS, BARK, LEAF, PICKET, PATH, CHROME, STONE, BALL = range(9)


def _materials() -> list[Material]:
    return [
        Material("soil", albedo=(0.2, 0.15, 0.1)),
        Material("grass", kind="plastic", albedo=(0.12, 0.4, 0.08), roughness=0.35),
        Material("bark", albedo=(0.3, 0.2, 0.12)),
        Material("leaf", kind="plastic", albedo=(0.1, 0.32, 0.06), roughness=0.25),
        Material("picket", albedo=(0.85, 0.85, 0.82)),
        Material("path", albedo=(1.0, 1.0, 1.0),
                 texture=textures.checker(64, 8, dark=(0.35, 0.2, 0.15), light=(0.8, 0.75, 0.65))),
        Material("chrome", kind="conductor", specular=(0.92, 0.92, 0.92), roughness=0.05),
        Material("stone", albedo=(0.6, 0.58, 0.55)),
        Material("ball", kind="plastic", albedo=(0.05, 0.12, 0.6), roughness=0.1),
    ]


def _lawn(rng: np.random.Generator) -> list:
    parts = [quad((-8.0, 0.0, 8.0), (16.0, 0.0, 0.0), (0.0, 0.0, -16.0), SOIL)]
    for _ in range(3000):
        x, z = rng.uniform(-4.0, 4.0), rng.uniform(-3.0, 3.5)
        if abs(x) < 0.7:  # the path
            continue
        height = rng.uniform(0.2, 0.45)
        lean = rng.normal(0.0, 0.07, 3) * np.array([1.0, 0.0, 1.0])
        parts.append(blade((x, 0.0, z), (0.0, height, 0.0), rng.uniform(0.01, 0.02), lean, GRASS, sections=2))
    return parts


def _shrub(rng: np.random.Generator) -> list:
    """Twigs and leaf blades around a trunk, in the shrub's own frame (base at the origin)."""
    parts = [tube((0.0, 0.0, 0.0), (0.0, 1.1, 0.0), 0.06, BARK, segments=8)]
    for _ in range(40):
        start = np.array([0.0, rng.uniform(0.5, 1.1), 0.0])
        d = rng.normal(0.0, 1.0, 3)
        d[1] = abs(d[1]) * 0.6 + 0.3
        d *= rng.uniform(0.5, 0.9) / np.linalg.norm(d)
        end = start + d
        parts.append(tube(start, end, 0.01, BARK, segments=4))
        for t in np.linspace(0.25, 1.0, 8):
            p = start + t * d
            leaf_dir = rng.normal(0.0, 1.0, 3) * 0.14
            parts.append(blade(p, leaf_dir, rng.uniform(0.05, 0.09), rng.normal(0.0, 0.02, 3), LEAF, sections=2))
    return parts


def _pickets() -> list:
    parts = [box((-4.0, 0.45, -3.05), (4.0, 0.52, -3.0), PICKET), box((-4.0, 0.95, -3.05), (4.0, 1.02, -3.0), PICKET)]
    for x in np.arange(-4.0, 4.01, 0.16):
        parts.append(box((x - 0.03, 0.0, -3.0), (x + 0.03, 1.15, -2.98), PICKET))
    return parts


def build():
    """Build the ``aa-garden`` scene."""
    rng = np.random.default_rng(31)
    path = quad((-0.7, 0.005, 8.0), (1.4, 0.0, 0.0), (0.0, 0.0, -16.0), PATH, uv_scale=(1.0, 11.0))
    column = join([tube((0.0, 0.0, 0.0), (0.0, 0.8, 0.0), 0.12, STONE, segments=16),
                   box((-0.2, 0.8, -0.2), (0.2, 0.86, 0.2), STONE)])
    sway = np.stack([translation((1.6, 0.0, -1.2)) @ rotation((1, 0, 0.4), 4.0 * np.sin(0.7 * k))
                     for k in range(FRAMES)])
    s = np.linspace(0.0, 1.0, FRAMES)
    ball_r = 0.25
    ball_z = -2.4 + 4.0 * s
    ball_t = np.stack([translation((0.0, ball_r + 0.005, z)) @ rotation((1, 0, 0), np.degrees((z + 2.4) / ball_r))
                       for z in ball_z])
    objects = [
        SceneObject("lawn", polydata(_lawn(rng))),
        SceneObject("path", polydata(path)),
        SceneObject("pickets", polydata(_pickets())),
        SceneObject("column", polydata(column.moved(translation((-1.5, 0.0, -0.8))))),
        SceneObject("gazing_ball", polydata(sphere(0.3, CHROME).moved(translation((-1.5, 1.16, -0.8))))),
        SceneObject("shrub", polydata(_shrub(rng)), transforms=sway),
        SceneObject("ball", polydata(sphere(ball_r, BALL)), transforms=ball_t),
    ]
    angle = np.radians(-25.0 + 40.0 * s)
    eyes = np.stack([4.2 * np.sin(angle), np.full(FRAMES, 1.4), 4.2 * np.cos(angle)], 1)
    targets = np.tile([0.0, 0.5, -0.8], (FRAMES, 1))
    return suite_scene(SPEC, objects=objects, materials=_materials(),
                       sun=sun((0.5, 0.7, 0.5), irradiance=2.2), environment=sky(),
                       camera=camera_path(eyes, targets, fov=50.0), max_depth=3)
