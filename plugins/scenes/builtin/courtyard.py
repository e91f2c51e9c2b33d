"""A San-Miguel-like courtyard: dense foliage, tables and chairs, a glossy floor, small objects.

Brick walls enclose a tiled court whose floor is a glossy plastic (it reflects the walls and the
tables). A tree with a dense canopy of small leaves and a vine-covered pergola throw dappled,
slightly soft shadows (sun of 1 degree radius); a grid of tables with chairs carries plates,
cups and bottles (many small objects, thin chair legs); a chrome ball sits on a fountain.

The sequence (32 frames) is a camera fly-through from the entrance towards the tree, while a
serving trolley rolls down the lane between the tables towards the camera (a moving object with
a moving shadow) and the tree's crown sways in the wind (dappled shadows that move over the
floor and the tables: the foliage case of temporal filters).
"""

from __future__ import annotations

import numpy as np

from harness import CameraPath, Material, Scene, SceneObject, rotation, translation

from . import textures
from .assemble import suite_scene
from .lighting import sky, sun
from .motion import along, swinging
from .primitives import arch_panel, box, canopy, cylinder, merge, plant, sphere, to_polydata

FRAMES = 32
TREE = (-4.8, 0.0, -3.8)  # foot of the trunk
TRUNK_HEIGHT = 3.2

SPEC = {
    "name": "courtyard",
    "tags": frozenset({"dynamic", "moving_shadow", "sun", "sky", "foliage", "glossy", "textured", "many_objects",
                       "indirect"}),
    "frames": FRAMES,
    "resolution": (192, 108),
}

HALF = 7.0  # the court spans [-HALF, HALF] in x and z
(BRICK, FLOOR, WOOD, CLOTH, LEAVES, BARK, CERAMIC, GLASS_GREEN, CHROME, STONE, POT) = range(11)


def _materials() -> list[Material]:
    return [
        Material("brick", albedo=(1.0, 1.0, 1.0), texture=textures.bricks(128, rows=8)),
        Material("glossy_tiles", kind="plastic", albedo=(1.0, 1.0, 1.0), roughness=0.06,
                 texture=textures.tiles(128, count=4, colors=((0.6, 0.55, 0.48), (0.3, 0.22, 0.16)))),
        Material("wood", albedo=(0.42, 0.26, 0.13)),
        Material("tablecloth", albedo=(0.8, 0.78, 0.72)),
        Material("leaves", albedo=(0.09, 0.3, 0.06)),
        Material("bark", albedo=(0.25, 0.18, 0.12)),
        Material("ceramic", kind="plastic", albedo=(0.85, 0.85, 0.82), roughness=0.1),
        Material("bottle_glass", kind="plastic", albedo=(0.05, 0.25, 0.08), roughness=0.05),
        Material("chrome", kind="conductor", specular=(0.9, 0.9, 0.9), roughness=0.02),
        Material("stone", albedo=(1.0, 1.0, 1.0), texture=textures.stone(64, seed=5, base=(0.7, 0.68, 0.64))),
        Material("terracotta", albedo=(0.6, 0.3, 0.17)),
    ]


def _walls() -> list:
    h = 6.0
    parts = [
        box((-HALF - 0.3, 0.0, -HALF - 0.3), (HALF + 0.3, h, -HALF), BRICK, uv_density=0.5),  # back
        box((-HALF - 0.3, 0.0, -HALF), (-HALF, h, HALF), BRICK, uv_density=0.5),  # left
        box((HALF, 0.0, -HALF), (HALF + 0.3, h, HALF), BRICK, uv_density=0.5),  # right
    ]
    # an arcade in front of the back wall
    for x in np.arange(-HALF + 1.0, HALF, 2.0):
        parts.append(arch_panel(2.0, 2.6, 3.8, 0.4, STONE, segments=10).transformed(translation((x, 0.0, -HALF + 1.5))))
    for x in np.arange(-HALF + 2.0, HALF, 2.0):
        parts.append(box((x - 0.15, 0.0, -HALF + 1.5), (x + 0.15, 2.6, -HALF + 1.9), STONE))
    parts.append(box((-HALF, 3.8, -HALF), (HALF, 4.0, -HALF + 1.9), STONE))
    return parts


def _table_set(rng: np.random.Generator, at: np.ndarray) -> tuple[list, list, list, list]:
    """One round table with chairs and tableware at ``at`` -> (wood, cloth, ceramic, glass) parts."""
    wood, cloth, ceramic, glass = [], [], [], []
    place = translation(at)
    cloth.append(cylinder(0.55, 0.03, CLOTH, segments=20).transformed(place @ translation((0, 0.75, 0))))
    wood.append(cylinder(0.04, 0.75, WOOD, segments=8, caps=False).transformed(place))
    wood.append(cylinder(0.25, 0.03, WOOD, segments=12).transformed(place))
    for k in range(int(rng.integers(2, 5))):
        angle = 90.0 * k + rng.uniform(-15, 15)
        chair = [box((-0.2, 0.42, -0.2), (0.2, 0.46, 0.2), WOOD), box((-0.2, 0.46, 0.17), (0.2, 0.95, 0.2), WOOD)]
        for lx in (-0.18, 0.18):
            for lz in (-0.18, 0.18):
                chair.append(box((lx - 0.015, 0.0, lz - 0.015), (lx + 0.015, 0.42, lz + 0.015), WOOD))
        m = place @ rotation((0, 1, 0), angle) @ translation((0, 0, 0.8))
        wood.append(merge(chair).transformed(m))
        plate = place @ rotation((0, 1, 0), angle) @ translation((0, 0.78, 0.35))
        ceramic.append(cylinder(0.11, 0.015, CERAMIC, segments=14).transformed(plate))
        ceramic.append(cylinder(0.035, 0.09, CERAMIC, segments=10, radius_top=0.045)
                       .transformed(plate @ translation((0.16, 0.0, 0.0))))
    for _ in range(int(rng.integers(1, 3))):
        spot = translation((rng.uniform(-0.15, 0.15), 0.78, rng.uniform(-0.15, 0.15)))
        glass.append(cylinder(0.035, 0.22, GLASS_GREEN, segments=10).transformed(place @ spot))
        glass.append(cylinder(0.035, 0.1, GLASS_GREEN, segments=10, radius_top=0.012)
                     .transformed(place @ spot @ translation((0, 0.22, 0))))
    return wood, cloth, ceramic, glass


def _trolley() -> list:
    """A serving trolley (two shelves on four legs) centred on the origin, standing on y = 0."""
    parts = [box((-0.3, 0.8, -0.45), (0.3, 0.84, 0.45), WOOD), box((-0.3, 0.3, -0.45), (0.3, 0.33, 0.45), WOOD)]
    for x in (-0.27, 0.27):
        for z in (-0.42, 0.42):
            parts.append(box((x - 0.02, 0.0, z - 0.02), (x + 0.02, 0.8, z + 0.02), WOOD))
    parts.append(cylinder(0.035, 0.22, GLASS_GREEN, segments=10).transformed(translation((0.1, 0.84, -0.2))))
    parts.append(cylinder(0.12, 0.02, CERAMIC, segments=14).transformed(translation((-0.1, 0.84, 0.15))))
    return parts


def build() -> Scene:
    """Build the ``courtyard`` scene (32 frames: fly-through, rolling trolley, swaying tree)."""
    rng = np.random.default_rng(11)
    floor = box((-HALF, -0.2, -HALF), (HALF, 0.0, HALF + 3.0), FLOOR, uv_density=0.5)
    wood, cloth, ceramic, glass = [], [], [], []
    for x in (-3.5, 0.0, 3.5):
        for z in (-1.5, 1.8):
            w, c, ce, g = _table_set(rng, np.array([x + rng.uniform(-0.3, 0.3), 0.0, z + rng.uniform(-0.3, 0.3)]))
            wood += w
            cloth += c
            ceramic += ce
            glass += g
    # a tree in the back left corner and a vine pergola over the right side
    trunk = cylinder(0.22, TRUNK_HEIGHT, BARK, segments=10, radius_top=0.12).transformed(translation(TREE))
    crown = canopy(rng, (-4.8, 4.0, -3.8), (2.2, 1.4, 2.2), LEAVES, n_leaves=1400, leaf_size=0.28)
    pergola = []
    for x in (3.0, 6.5):
        for z in (-4.5, -0.5, 3.5):
            pergola.append(box((x - 0.08, 0.0, z - 0.08), (x + 0.08, 3.0, z + 0.08), WOOD))
    for z in np.arange(-4.6, 3.7, 0.4):
        pergola.append(box((2.8, 3.0, z - 0.03), (6.7, 3.08, z + 0.03), WOOD))
    vines = canopy(rng, (4.75, 3.15, -0.5), (2.0, 0.12, 4.0), LEAVES, n_leaves=700, leaf_size=0.22)
    # fountain with a chrome ball; potted plants along the left wall
    fountain = [cylinder(0.9, 0.45, STONE, segments=24), cylinder(0.15, 0.9, STONE, segments=10)]
    ball = sphere(0.3, CHROME, rings=14, segments=28).transformed(translation((0.0, 1.2, 0.0)))
    at_fountain = translation((-1.5, 0.0, 4.5))
    pots, greens = [], []
    for z in (-1.0, 1.5, 4.0):
        at = translation((-HALF + 0.6, 0.0, z))
        pots.append(cylinder(0.3, 0.55, POT, segments=12, radius_top=0.38).transformed(at))
        clump = plant(rng, LEAVES, n_leaves=45, height=0.8, leaf_length=0.5)
        greens.append(clump.transformed(at @ translation((0, 0.5, 0))))
    objects = [
        SceneObject("floor", to_polydata(floor)),
        SceneObject("walls", to_polydata(_walls())),
        SceneObject("furniture", to_polydata(wood + pergola)),
        SceneObject("tablecloths", to_polydata(cloth)),
        SceneObject("tableware", to_polydata(ceramic + glass)),
        SceneObject("trunk", to_polydata(trunk)),
        SceneObject("crown", to_polydata(crown),
                    transforms=swinging((TREE[0], TRUNK_HEIGHT, TREE[2]), (1.0, 0.0, 0.6), amplitude=4.0,
                                        periods=1.5, frames=FRAMES)),
        SceneObject("vines", to_polydata(vines)),
        SceneObject("fountain", to_polydata([p.transformed(at_fountain) for p in fountain])),
        SceneObject("chrome_ball", to_polydata(ball.transformed(at_fountain))),
        SceneObject("plants", to_polydata(pots + greens)),
        SceneObject("trolley", to_polydata(_trolley()),
                    transforms=np.stack([translation((-1.75, 0.0, z)) for z in np.linspace(-3.5, 2.6, FRAMES)])),
    ]
    eye = along([(3.5, 3.6, 9.8), (1.5, 2.9, 8.2), (-1.0, 2.3, 6.8)], FRAMES)
    target = along([(-0.5, 0.6, -1.0), (-2.0, 1.0, -2.0), (-4.0, 1.8, -3.0)], FRAMES)
    camera = CameraPath(positions=eye, targets=target, fov=55.0, near=0.05, far=100.0)
    return suite_scene(
        SPEC,
        objects=objects,
        materials=_materials(),
        sun=sun((-0.45, 0.8, 0.35), irradiance=4.5, angular_radius=1.0),
        environment=sky(0.7),
        camera=camera,
        max_depth=5,
    )
