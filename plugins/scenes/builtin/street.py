"""A dynamic street: 24 frames with a moving camera and a car driving past.

A street canyon between facades with windows, sidewalks with lamp posts and bollards, emissive
shop signs and a low sun (long hard shadows). The camera walks along the sidewalk and pans while
a glossy car with rolling wheels crosses the view: objects near the camera slide against the
background (parallax) and the car uncovers what it hid, so every frame has disoccluded pixels.
"""

from __future__ import annotations

import numpy as np

from harness import CameraPath, Material, Scene, SceneObject, rotation, translation

from . import textures
from .assemble import suite_scene
from .lighting import sky, sun
from .primitives import box, cylinder, merge, to_polydata

FRAMES = 24
SPEC = {
    "name": "street",
    "tags": frozenset({"dynamic", "sun", "sky", "glossy", "emissive", "disocclusion", "hard_shadows",
                       "textured"}),
    "frames": FRAMES,
    "resolution": (192, 108),
}

ASPHALT, SIDEWALK, FACADE_A, FACADE_B, METAL, LAMP, SIGN_WARM, SIGN_BLUE, PAINT, TIRE, WINDOW = range(11)
WHEEL_RADIUS = 0.33


def _materials() -> list[Material]:
    return [
        Material("asphalt", kind="plastic", albedo=(0.07, 0.07, 0.075), roughness=0.25),
        Material("sidewalk", albedo=(1.0, 1.0, 1.0),
                 texture=textures.tiles(64, count=2, colors=((0.5, 0.5, 0.48), (0.45, 0.45, 0.44)))),
        Material("facade_a", kind="plastic", albedo=(1.0, 1.0, 1.0), roughness=0.12,
                 texture=textures.windows(128, 4, 4)),
        Material("facade_b", kind="plastic", albedo=(1.0, 1.0, 1.0), roughness=0.12,
                 texture=textures.windows(128, 3, 5, wall=(0.62, 0.45, 0.35))),
        Material("metal", kind="conductor", specular=(0.6, 0.6, 0.62), roughness=0.3),
        Material("lamp", albedo=(0.9, 0.9, 0.9), emission=(12.0, 10.0, 7.0)),
        Material("sign_warm", albedo=(0.9, 0.6, 0.3), emission=(6.0, 3.0, 1.0)),
        Material("sign_blue", albedo=(0.3, 0.5, 0.9), emission=(0.8, 2.0, 6.0)),
        Material("car_paint", kind="plastic", albedo=(0.6, 0.04, 0.03), roughness=0.04),
        Material("tire", albedo=(0.03, 0.03, 0.03)),
        Material("car_window", kind="conductor", specular=(0.08, 0.08, 0.09), roughness=0.02),
    ]


def _buildings(rng: np.random.Generator) -> list:
    parts = []
    for sign in (-1.0, 1.0):
        x = -40.0
        k = 0
        while x < 40.0:
            width = rng.uniform(6.0, 10.0)
            height = rng.uniform(7.0, 16.0)
            depth = 8.0
            z0 = sign * 6.5
            lo = (x, 0.0, min(z0, z0 + sign * depth))
            hi = (x + width - 0.4, height, max(z0, z0 + sign * depth))
            parts.append(box(lo, hi, FACADE_A if k % 2 == 0 else FACADE_B, uv_density=0.25))
            if rng.random() < 0.6:  # a shop sign at ground level
                zs = z0 - sign * 0.05
                lo_z, hi_z = min(zs, zs - sign * 0.1), max(zs, zs - sign * 0.1)
                parts.append(box((x + 1.0, 2.6, lo_z), (x + width - 1.5, 3.2, hi_z),
                                 SIGN_WARM if rng.random() < 0.5 else SIGN_BLUE))
            x += width
            k += 1
    return parts


def _street_furniture() -> list:
    parts = []
    for x in np.arange(-36.0, 37.0, 9.0):
        for sign in (-1.0, 1.0):
            z = sign * 4.4
            parts.append(cylinder(0.07, 5.0, METAL, segments=8).transformed(translation((x, 0.15, z))))
            parts.append(box((x - 0.3, 5.0, z - 0.15), (x + 0.3, 5.15, z + 0.15), METAL))
            parts.append(box((x - 0.25, 4.95, z - 0.12), (x + 0.25, 5.0, z + 0.12), LAMP))
    for x in np.arange(-12.0, 12.0, 1.6):  # bollards along the near kerb
        parts.append(cylinder(0.1, 0.9, METAL, segments=10).transformed(translation((x, 0.15, 4.25))))
    return parts


def _car() -> tuple:
    body = merge([
        box((-2.1, 0.3, -0.85), (2.1, 0.95, 0.85), PAINT),
        box((-1.1, 0.95, -0.78), (1.0, 1.45, 0.78), PAINT),
    ])
    windows = merge([
        box((-1.05, 1.0, -0.8), (0.95, 1.38, -0.78), WINDOW),
        box((-1.05, 1.0, 0.78), (0.95, 1.38, 0.8), WINDOW),
        box((0.95, 1.0, -0.72), (1.02, 1.38, 0.72), WINDOW),
    ])
    wheel = cylinder(WHEEL_RADIUS, 0.22, TIRE, segments=14)
    wheel = wheel.transformed(rotation((1, 0, 0), 90) @ translation((0, -0.11, 0)))
    hub = box((-0.12, -0.12, -0.13), (0.12, 0.12, 0.13), METAL)  # visible spokes make rotation measurable
    return merge([body, windows]), merge([wheel, hub])


def _car_transforms() -> tuple[np.ndarray, list[np.ndarray]]:
    xs = np.linspace(-14.0, 10.0, FRAMES)
    body = np.stack([translation((x, 0.0, -1.8)) for x in xs])
    wheels = []
    for ox, oz in ((-1.35, -0.85), (1.35, -0.85), (-1.35, 0.85), (1.35, 0.85)):
        frames = []
        for x in xs:
            roll = -np.degrees((x - xs[0]) / WHEEL_RADIUS)  # rolling without slipping towards +x
            frames.append(translation((x + ox, WHEEL_RADIUS, -1.8 + oz)) @ rotation((0, 0, 1), roll))
        wheels.append(np.stack(frames))
    return body, wheels


def build() -> Scene:
    """Build the ``street`` scene (24 frames)."""
    rng = np.random.default_rng(5)
    ground = merge([
        box((-45.0, -0.2, -4.0), (45.0, 0.0, 4.0), ASPHALT, uv_density=0.2),
        box((-45.0, -0.2, 4.0), (45.0, 0.15, 6.5), SIDEWALK, uv_density=0.5),
        box((-45.0, -0.2, -6.5), (45.0, 0.15, -4.0), SIDEWALK, uv_density=0.5),
    ])
    body, wheel = _car()
    body_t, wheel_t = _car_transforms()
    objects = [
        SceneObject("ground", to_polydata(ground)),
        SceneObject("buildings", to_polydata(_buildings(rng))),
        SceneObject("street_furniture", to_polydata(_street_furniture())),
        SceneObject("car", to_polydata(body), transforms=body_t),
    ]
    for k, t in enumerate(wheel_t):
        objects.append(SceneObject(f"wheel_{k}", to_polydata(wheel), transforms=t))
    s = np.linspace(0.0, 1.0, FRAMES)[:, None]
    eye = (1 - s) * np.array([-7.0, 1.7, 5.6]) + s * np.array([1.0, 1.75, 5.3])
    target = (1 - s) * np.array([4.0, 1.3, -3.0]) + s * np.array([9.0, 1.6, -4.0])
    camera = CameraPath(positions=eye, targets=target, fov=55.0, near=0.05, far=200.0)
    return suite_scene(
        SPEC,
        objects=objects,
        materials=_materials(),
        sun=sun((-0.6, 0.42, 0.55), irradiance=4.0, angular_radius=0.27),
        environment=sky(0.8),
        camera=camera,
        max_depth=5,
    )
