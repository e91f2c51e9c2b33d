"""A Sponza-like atrium: two storeys of arcades around an open court.

Stone colonnades with round arches on both long sides carry a gallery and an aisle roof; the
court is open to the sky and lit by a sun at about 60 degrees elevation, so the floor and the
upper arcade get hard shadows while the aisles behind the columns are lit only indirectly (dark
regions). Striped cloth banners hang from the upper arcade (thin, folded geometry) and potted
plants with thin leaves stand along the court.

The sequence (32 frames) is a camera fly-through along the court, turning towards the far
arcade, while a striped ball rolls across the sunlit floor (a moving object with a moving hard
shadow, the case where temporal filters lag) and one banner swings on its rail (a thin moving
shadow on the columns and the floor).
"""

from __future__ import annotations

import numpy as np

from harness import CameraPath, Material, Scene, SceneObject, rotation, translation

from . import textures
from .assemble import suite_scene
from .lighting import sky, sun
from .motion import along, rolling, swinging
from .primitives import arch_panel, box, cloth, cylinder, merge, plant, sphere, to_polydata

LENGTH = 16.0  # court length along x (m)
COURT = 4.0  # half-width of the court (colonnade line at z = +-COURT)
AISLE = 3.0  # aisle depth behind the colonnades
BAY = 2.0  # column spacing
HEIGHT = 8.5  # top of the aisle roof

FRAMES = 32
BALL_RADIUS = 0.45
SWINGING_BANNER = 3  # index in _banners(): x = 11 on the +z side

STONE, FLOOR, MARBLE, BANNER_RED, BANNER_BLUE, LEAVES, POT, SOIL, BALL = range(9)


def _materials() -> list[Material]:
    return [
        Material("stone", albedo=(1.0, 1.0, 1.0), texture=textures.stone(128, seed=1)),
        Material("floor", albedo=(1.0, 1.0, 1.0), texture=textures.tiles(128, count=4)),
        Material("marble", kind="plastic", albedo=(0.78, 0.76, 0.72), roughness=0.15),
        Material("banner_red", albedo=(1.0, 1.0, 1.0), texture=textures.stripes(64, 6)),
        Material("banner_blue", albedo=(1.0, 1.0, 1.0),
                 texture=textures.stripes(64, 4, a=(0.08, 0.15, 0.55), b=(0.8, 0.8, 0.75))),
        Material("leaves", albedo=(0.12, 0.38, 0.07)),
        Material("terracotta", albedo=(0.6, 0.3, 0.17)),
        Material("soil", albedo=(0.12, 0.08, 0.05)),
        Material("ball", kind="plastic", albedo=(1.0, 1.0, 1.0), roughness=0.3,
                 texture=textures.stripes(64, 4, a=(0.75, 0.6, 0.1), b=(0.1, 0.25, 0.6))),
    ]


def _side(sign: float):
    """Colonnades, gallery and aisle of the side at z = sign * COURT; returns (stone, marble) parts."""
    stone, marble = [], []
    # columns of both storeys
    for x in np.arange(BAY, LENGTH, BAY):
        marble.append(cylinder(0.22, 3.0, MARBLE, segments=16).transformed(translation((x, 0.0, sign * COURT))))
        marble.append(cylinder(0.18, 2.5, MARBLE, segments=16).transformed(translation((x, 4.5, sign * COURT))))
    # arcades: one arch panel per bay and storey (panel built in x-y, extruded along z)
    for xc in np.arange(BAY / 2, LENGTH, BAY):
        for spring, top in ((3.0, 4.2), (7.0, 8.2)):
            panel = arch_panel(BAY, spring, top, 0.5, STONE, segments=12)
            stone.append(panel.transformed(translation((xc, 0.0, sign * COURT - 0.25))))
    # gallery floor and aisle roof, outer wall, balustrade of the gallery
    z_in, z_out = sign * (COURT - 0.25), sign * (COURT + AISLE)
    lo, hi = min(z_in, z_out), max(z_in, z_out)
    stone.append(box((0.0, 4.2, lo), (LENGTH, 4.5, hi), STONE, uv_density=0.5))
    stone.append(box((0.0, 8.2, lo), (LENGTH, HEIGHT, hi), STONE, uv_density=0.5))
    wall = (z_out, z_out + sign * 0.3)
    stone.append(box((0.0, 0.0, min(wall)), (LENGTH, HEIGHT, max(wall)), STONE, uv_density=0.5))
    rail_z = sign * (COURT - 0.05)
    stone.append(box((0.0, 5.35, rail_z - 0.08), (LENGTH, 5.45, rail_z + 0.08), STONE, uv_density=0.5))
    for x in np.arange(0.25, LENGTH, 0.5):
        marble.append(cylinder(0.04, 0.85, MARBLE, segments=6, caps=False).transformed(translation((x, 4.5, rail_z))))
    return stone, marble


def _banners() -> list:
    parts = []
    for k, (x, sign) in enumerate(((5.0, -1), (11.0, -1), (5.0, 1), (11.0, 1))):
        material = BANNER_RED if k % 2 == 0 else BANNER_BLUE
        sheet = cloth(1.1, 3.2, material, folds=3, amplitude=0.07, nu=14, nv=28, sway=0.15, seed=k)
        m = translation((x, 8.1, sign * (COURT - 0.45)))
        if sign < 0:  # the sheet faces -z; turn the banners of the -z side towards the court
            m = m @ rotation((0, 1, 0), 180)
        parts.append(sheet.transformed(m))
    return parts


def _plants(rng: np.random.Generator) -> tuple[list, list, list]:
    pots, soil, leaves = [], [], []
    for x in (3.0, 8.0, 13.0):
        for sign in (-1, 1):
            at = translation((x, 0.0, sign * (COURT - 1.0)))
            pots.append(cylinder(0.32, 0.6, POT, segments=14, radius_top=0.42).transformed(at))
            soil.append(cylinder(0.4, 0.01, SOIL, segments=14, caps=True).transformed(at @ translation((0, 0.55, 0))))
            leaves.append(plant(rng, LEAVES, n_leaves=60, height=0.9, leaf_length=0.55, leaf_width=0.07)
                          .transformed(at @ translation((0, 0.55, 0))))
    return pots, soil, leaves

SPEC = {
    "name": "atrium",
    "tags": frozenset({"dynamic", "moving_shadow", "sun", "sky", "hard_shadows", "indirect", "foliage", "cloth",
                       "textured", "dark_regions"}),
    "frames": FRAMES,
    "resolution": (192, 108),
}


def build() -> Scene:
    """Build the ``atrium`` scene (32 frames: fly-through, rolling ball, swinging banner)."""
    rng = np.random.default_rng(7)
    stone, marble = [], []
    for sign in (-1.0, 1.0):
        s, m = _side(sign)
        stone += s
        marble += m
    width = COURT + AISLE + 0.3
    stone.append(box((-0.3, 0.0, -width), (0.0, HEIGHT + 1.0, width), STONE, uv_density=0.5))
    stone.append(box((LENGTH, 0.0, -width), (LENGTH + 0.3, HEIGHT + 1.0, width), STONE, uv_density=0.5))
    floor = box((-0.3, -0.2, -width), (LENGTH + 0.3, 0.0, width), FLOOR, uv_density=0.5)
    pots, soil, leaves = _plants(rng)
    banners = _banners()
    swing = banners.pop(SWINGING_BANNER)
    rail = (11.0, 8.1, COURT - 0.45)  # where the swinging banner hangs from
    ball = sphere(BALL_RADIUS, BALL, rings=12, segments=24)
    objects = [
        SceneObject("floor", to_polydata(floor)),
        SceneObject("stonework", to_polydata(stone)),
        SceneObject("columns", to_polydata(marble)),
        SceneObject("banners", to_polydata(banners)),
        SceneObject("pots", to_polydata(merge(pots + soil))),
        SceneObject("plants", to_polydata(leaves)),
        SceneObject("ball", to_polydata(ball),
                    transforms=rolling((11.6, BALL_RADIUS, -3.0), (10.6, BALL_RADIUS, 2.6), BALL_RADIUS, FRAMES)),
        SceneObject("swinging_banner", to_polydata(swing),
                    transforms=swinging(rail, (1.0, 0.0, 0.0), amplitude=14.0, periods=1.0, frames=FRAMES)),
    ]
    eye = along([(0.7, 1.7, -1.2), (3.5, 1.9, -0.6), (6.5, 2.3, 0.6)], FRAMES)
    target = along([(LENGTH, 4.2, 1.0), (LENGTH, 3.0, -0.5), (13.0, 1.2, -1.5)], FRAMES)
    camera = CameraPath(positions=eye, targets=target, fov=62.0, near=0.05, far=100.0)
    return suite_scene(
        SPEC,
        objects=objects,
        materials=_materials(),
        sun=sun((0.35, 1.0, -0.45), irradiance=5.0, angular_radius=0.5),
        environment=sky(0.8),
        camera=camera,
        max_depth=5,
    )
