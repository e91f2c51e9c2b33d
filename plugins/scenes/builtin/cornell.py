"""The classic Cornell box: white floor, ceiling and back wall, red left and green right wall,
a tall and a short block, and a square area light just below the ceiling (soft shadows,
colour bleeding). Dimensions follow the measured box (5.55 m wide) scaled to metres.

The sequence (8 frames, static camera) slides and turns the short block towards the middle of
the floor: its soft shadow and the light it bounces onto the walls move with it."""

from __future__ import annotations

import numpy as np

from harness import CameraPath, Material, Scene, SceneObject, rotation, translation

from .assemble import suite_scene
from .primitives import box, grid, merge, to_polydata

W = 5.56  # box width, depth and height (m)


def _block(size, angle, position, material):
    half = np.array([size[0] / 2, 0.0, size[2] / 2])
    part = box(-half, half + np.array([0, size[1], 0]), material)
    return part.transformed(translation(position) @ rotation((0, 1, 0), angle))

FRAMES = 8

SPEC = {
    "name": "cornell",
    "tags": frozenset({"dynamic", "moving_shadow", "emissive", "soft_shadows", "indirect"}),
    "frames": FRAMES,
    "resolution": (128, 128),
}


def build() -> Scene:
    """Build the ``cornell`` scene (8 frames: the short block slides and turns)."""
    materials = [
        Material("white", albedo=(0.73, 0.73, 0.73)),
        Material("red", albedo=(0.63, 0.065, 0.05)),
        Material("green", albedo=(0.14, 0.45, 0.091)),
        Material("light", albedo=(0.78, 0.78, 0.78), emission=(17.0, 12.0, 4.0)),
    ]
    white, red, green, light = range(4)
    x, y, z = np.eye(3) * W
    room = merge([
        grid((0, 0, 0), z, x, white),  # floor, facing +y
        grid((0, W, 0), x, z, white),  # ceiling, facing -y
        grid((0, 0, 0), x, y, white),  # back wall, facing +z
        grid((0, 0, 0), y, z, red),  # left wall, facing +x
        grid((W, 0, 0), z, y, green),  # right wall, facing -x
    ])
    objects = [SceneObject("room", to_polydata(room))]
    objects.append(SceneObject("tall_block", to_polydata(_block((1.66, 3.3, 1.66), 17.0, (1.85, 0.0, 2.2), white))))
    short = to_polydata(_block((1.66, 1.65, 1.66), 0.0, (0.0, 0.0, 0.0), white))
    path = zip(np.linspace(3.7, 3.1, FRAMES), np.linspace(3.6, 3.1, FRAMES), np.linspace(-17.0, 8.0, FRAMES))
    moves = np.stack([translation((x, 0.0, z)) @ rotation((0, 1, 0), a) for x, z, a in path])
    objects.append(SceneObject("short_block", short, transforms=moves))
    s = 1.3
    lamp = grid((W / 2 - s / 2, W - 0.01, W / 2 - s / 2), (s, 0, 0), (0, 0, s), light)
    objects.append(SceneObject("light", to_polydata(lamp)))
    camera = CameraPath(positions=[(W / 2, W / 2, W + 8.0)], targets=[(W / 2, W / 2, 0.0)], fov=39.3,
                        near=0.1, far=100.0)
    return suite_scene(
        SPEC,
        objects=objects,
        materials=materials,
        camera=camera,
        max_depth=8,
    )
