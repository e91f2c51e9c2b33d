"""Light and scene assembly shared by the anti-aliasing scenes."""

from __future__ import annotations

import numpy as np

from harness import CameraPath, Environment, Scene, Sun

#: the ``source`` of every anti-aliasing scene
SOURCE = "plugins.scenes.antialias"
#: angular radius of the sun's disc, degrees
SUN_RADIUS = 0.27


def sun(direction, irradiance: float, tint=(1.0, 0.95, 0.88)) -> Sun:
    """A sun whose disc delivers ``irradiance`` at normal incidence (radiance = E / solid angle)."""
    solid_angle = 2.0 * np.pi * (1.0 - np.cos(np.radians(SUN_RADIUS)))
    return Sun(direction=tuple(direction), angular_radius=SUN_RADIUS,
               radiance=tuple(np.asarray(tint, float) * irradiance / solid_angle))


def sky(scale: float = 1.0) -> Environment:
    """A blue-to-hazy gradient sky (zenith to horizon), dim enough that lit surfaces stay below 1."""
    return Environment(kind="sky", radiance=(0.12 * scale, 0.2 * scale, 0.42 * scale),
                       horizon=(0.5 * scale, 0.55 * scale, 0.6 * scale))


def camera_path(eyes, targets, fov: float) -> CameraPath:
    """A camera following the rows of ``eyes`` and ``targets`` (one per frame)."""
    return CameraPath(positions=np.asarray(eyes, float), targets=np.asarray(targets, float), fov=fov,
                      near=0.05, far=300.0)


def suite_scene(spec: dict, **fields) -> Scene:
    """A :class:`harness.Scene` with the name, frames, resolution and tags of a builder's ``SPEC``."""
    return Scene(name=spec["name"], frame_count=spec["frames"], resolution=spec["resolution"], tags=spec["tags"],
                 source=SOURCE, **fields)

