"""The raster renderer's cheap local shading (no shadows, no interreflection).

``color = albedo * (ambient + sun) + emission`` for surfaces, where ``ambient`` is the mean
radiance of the environment (a diffuse surface under a uniform, unoccluded environment of
radiance L reflects ``albedo * L``) and ``sun = E_sun * max(0, n.l) / pi`` with the sun's
irradiance ``E_sun = L_sun * 2 pi (1 - cos r)``. A scene with neither sun nor environment is lit
by a headlight: ``albedo * HEADLIGHT * max(0, n.v)``. Background pixels show the environment
(and the sun's disc). This is what anti-aliasing filters are judged on; it is not a light
transport solution.
"""

from __future__ import annotations

import numpy as np

HEADLIGHT = 0.8  # radiance-like scale of the headlight term


def environment_image(environment) -> np.ndarray | None:
    """The equirectangular map of a ``map`` environment as (h, w, 3) float32, else None."""
    if environment is None or environment.kind != "map" or environment.image is None:
        return None
    return environment.image_array()


def environment_radiance(environment, directions: np.ndarray, image: np.ndarray | None = None) -> np.ndarray:
    """Radiance (..., 3) float32 arriving from unit ``directions`` (..., 3); zero without environment.

    ``sky`` blends linearly from ``horizon`` (at and below the horizon) to ``radiance`` at the
    zenith in the sine of the elevation; ``map`` looks an equirectangular image up (nearest
    texel) with ``u = 0.5 + atan2(d_x, -d_z) / 2 pi + rotation / 360``, ``v = acos(d_y) / pi``
    (row 0 at the zenith).
    """
    shape = directions.shape[:-1] + (3,)
    if environment is None:
        return np.zeros(shape, np.float32)
    radiance = np.asarray(environment.radiance, np.float32)
    if environment.kind == "constant":
        return np.broadcast_to(radiance, shape).astype(np.float32)
    if environment.kind == "sky":
        t = np.clip(directions[..., 1:2], 0.0, 1.0).astype(np.float32)
        return (np.asarray(environment.horizon, np.float32) * (1 - t) + radiance * t).astype(np.float32)
    if image is None:
        return np.broadcast_to(radiance, shape).astype(np.float32)
    h, w = image.shape[:2]
    u = 0.5 + np.arctan2(directions[..., 0], -directions[..., 2]) / (2 * np.pi) + environment.rotation / 360.0
    v = np.arccos(np.clip(directions[..., 1], -1.0, 1.0)) / np.pi
    col = np.floor(np.mod(u, 1.0) * w).astype(np.int64) % w
    row = np.clip(np.floor(v * h).astype(np.int64), 0, h - 1)
    return (image[row, col] * radiance).astype(np.float32)


def ambient_radiance(environment, image: np.ndarray | None = None) -> np.ndarray:
    """Mean radiance (3,) of the environment over the sphere of directions (approximate for ``sky``)."""
    if environment is None:
        return np.zeros(3, np.float32)
    radiance = np.asarray(environment.radiance, np.float32)
    if environment.kind == "constant":
        return radiance
    if environment.kind == "sky":
        # upper hemisphere averages to (horizon + zenith) / 2, the lower one is horizon
        return (0.75 * np.asarray(environment.horizon, np.float32) + 0.25 * radiance).astype(np.float32)
    if image is None:
        return radiance
    rows = image.shape[0]
    weights = np.sin((np.arange(rows) + 0.5) / rows * np.pi)  # solid angle of each latitude row
    mean = (image.mean(axis=1) * weights[:, None]).sum(axis=0) / weights.sum()
    return (mean * radiance).astype(np.float32)


def sun_irradiance(sun) -> np.ndarray:
    """Irradiance (3,) of the sun's disc at normal incidence."""
    solid_angle = 2.0 * np.pi * (1.0 - np.cos(np.radians(sun.angular_radius)))
    return (np.asarray(sun.radiance, np.float64) * solid_angle).astype(np.float32)


def shade(scene, hit: np.ndarray, albedo: np.ndarray, normal: np.ndarray, emission: np.ndarray,
          directions: np.ndarray, env_image: np.ndarray | None) -> np.ndarray:
    """Colour (H, W, 3) float32 of the cheap shading model described in this module.

    Parameters
    ----------
    scene : harness.Scene
    hit : ndarray (H, W) bool
        Pixels that see a surface.
    albedo, normal, emission : ndarray (H, W, 3)
        Per-pixel surface values (ignored where not ``hit``).
    directions : ndarray (H, W, 3)
        Unit primary-ray directions.
    env_image : ndarray or None
        The environment map, from :func:`environment_image`.
    """
    light = np.broadcast_to(ambient_radiance(scene.environment, env_image), albedo.shape).astype(np.float32)
    if scene.sun is not None:
        cos = np.clip(normal @ np.asarray(scene.sun.direction, np.float32), 0.0, None)[..., None]
        light = light + sun_irradiance(scene.sun) * cos / np.float32(np.pi)
    if scene.sun is None and scene.environment is None:
        cos = np.clip(-(normal * directions).sum(axis=-1), 0.0, None)[..., None]
        light = light + np.float32(HEADLIGHT) * cos
    color = albedo * light + emission
    background = environment_radiance(scene.environment, directions[~hit], env_image)
    if scene.sun is not None and len(background):
        cos_r = np.cos(np.radians(scene.sun.angular_radius))
        in_disc = directions[~hit] @ np.asarray(scene.sun.direction) >= cos_r
        background[in_disc] += np.asarray(scene.sun.radiance, np.float32)
    color[~hit] = background
    return color.astype(np.float32)
