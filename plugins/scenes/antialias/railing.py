"""``aa-railing``: a terrace railing against a checkered plaza, wires and a rolling glossy ball.

The camera strafes along a terrace behind a metal railing (balusters 2.4 cm thick, a round
handrail) and looks over a plaza paved with a 25 cm checkerboard that runs to the horizon
(50 cm squares, minification moire), towards a billboard of small text and power lines a few centimetres thick
(sub-pixel far away). A glossy red ball rolls across the plaza (disocclusions, a moving
highlight) and a gold ring turns on a plinth (curved specular highlights). 24 frames.
"""

from __future__ import annotations

import numpy as np

from harness import Material, SceneObject, rotation, translation

from . import textures
from .daylight import camera_path, sky, suite_scene, sun
from .geometry import box, join, polydata, quad, sphere, torus, tube

FRAMES = 24
SPEC = {
    "name": "aa-railing",
    "tags": frozenset({"antialias", "dynamic", "thin", "texture", "specular", "sun", "sky", "disocclusion"}),
    "frames": FRAMES,
    "resolution": (320, 180),
}

PLAZA, METAL, BILLBOARD, POLE, WIRE, BALL, GOLD, STONE = range(8)


def _materials() -> list[Material]:
    return [
        Material("plaza", albedo=(1.0, 1.0, 1.0), texture=textures.checker(64, 8)),
        Material("railing", kind="conductor", specular=(0.75, 0.75, 0.78), roughness=0.18),
        Material("billboard", albedo=(1.0, 1.0, 1.0), texture=textures.glyphs(256, 16, seed=11)),
        Material("pole", albedo=(0.25, 0.22, 0.2)),
        Material("wire", albedo=(0.05, 0.05, 0.05)),
        Material("ball", kind="plastic", albedo=(0.7, 0.05, 0.04), roughness=0.08),
        Material("gold", kind="conductor", specular=(0.95, 0.7, 0.3), roughness=0.12),
        Material("stone", albedo=(0.55, 0.53, 0.5)),
    ]


def _railing() -> list:
    parts = [tube((-9.0, 1.0, 2.0), (9.0, 1.0, 2.0), 0.03, METAL, segments=12),
             tube((-9.0, 0.12, 2.0), (9.0, 0.12, 2.0), 0.015, METAL)]
    for x in np.arange(-9.0, 9.01, 0.14):
        parts.append(tube((x, 0.12, 2.0), (x, 1.0, 2.0), 0.012, METAL, segments=6))
    return parts


def _wires() -> list:
    parts = []
    for x in (-30.0, 30.0):
        parts.append(tube((x, 0.0, -45.0), (x, 11.0, -45.0), 0.15, POLE))
    for k, y in enumerate((10.6, 10.0, 9.4, 8.8)):
        sag = 0.6 + 0.1 * k
        points = [(x, y - sag * (1.0 - (x / 30.0) ** 2), -45.0 + 0.3 * k) for x in np.linspace(-30.0, 30.0, 13)]
        parts += [tube(a, b, 0.02, WIRE, segments=5) for a, b in zip(points[:-1], points[1:])]
    return parts


def build():
    """Build the ``aa-railing`` scene."""
    plaza = quad((-60.0, 0.0, 60.0), (120.0, 0.0, 0.0), (0.0, 0.0, -120.0), PLAZA, uv_scale=(30.0, 30.0))
    billboard = join([
        quad((-9.0, 2.5, -40.0), (18.0, 0.0, 0.0), (0.0, 6.0, 0.0), BILLBOARD, uv_scale=(3.0, 1.0)),
        tube((-7.0, 0.0, -40.2), (-7.0, 2.5, -40.2), 0.2, POLE),
        tube((7.0, 0.0, -40.2), (7.0, 2.5, -40.2), 0.2, POLE),
    ])
    plinth = box((2.4, 0.0, -6.6), (3.6, 0.8, -5.4), STONE)
    s = np.linspace(0.0, 1.0, FRAMES)
    radius = 0.6
    ball_x = -5.0 + 9.0 * s
    ball_t = np.stack([translation((x, radius, -4.0)) @ rotation((0, 0, 1), -np.degrees((x + 5.0) / radius))
                       for x in ball_x])
    ring_t = np.stack([translation((3.0, 1.6, -6.0)) @ rotation((0.3, 1.0, 0.0), 15.0 * k) @ rotation((1, 0, 0), 70.0)
                       for k in range(FRAMES)])
    objects = [
        SceneObject("plaza", polydata(plaza)),
        SceneObject("railing", polydata(_railing())),
        SceneObject("billboard", polydata(billboard)),
        SceneObject("wires", polydata(_wires())),
        SceneObject("plinth", polydata(plinth)),
        SceneObject("ball", polydata(sphere(radius, BALL)), transforms=ball_t),
        SceneObject("ring", polydata(torus(0.55, 0.12, GOLD)), transforms=ring_t),
    ]
    eyes = np.stack([-1.6 + 3.2 * s, np.full(FRAMES, 1.25), np.full(FRAMES, 6.0)], 1)
    targets = np.stack([-0.6 + 1.6 * s, np.full(FRAMES, 0.4), np.full(FRAMES, -10.0)], 1)
    return suite_scene(SPEC, objects=objects, materials=_materials(),
                       sun=sun((-0.45, 0.55, 0.7), irradiance=2.2), environment=sky(),
                       camera=camera_path(eyes, targets, fov=50.0), max_depth=3)
