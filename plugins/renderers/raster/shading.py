"""The raster renderer's cheap local shading (no shadows, no interreflection), one Numba pass.

``color = albedo * (ambient + sun) + specular + emission`` for surfaces, where ``ambient`` is
the mean radiance of the environment (a diffuse surface under a uniform, unoccluded environment
of radiance L reflects ``albedo * L``) and ``sun = E_sun * max(0, n.l) / pi`` with the sun's
irradiance ``E_sun = L_sun * 2 pi (1 - cos r)``. ``specular`` is the sun's GGX lobe on
``plastic``, ``conductor`` and ``mirror`` materials (:func:`ggx_lobe`), so curved glossy
surfaces carry small, bright highlights (shading aliasing). Metals (``conductor``, ``mirror``)
have no diffuse term: they reflect the environment in the mirror direction, weighted by
Schlick's Fresnel ``F0 + (1 - F0)(1 - n.v)^5`` (roughness is ignored there; the sky is smooth),
when the scene has an environment. A scene with neither sun nor environment is lit by a
headlight: ``albedo * HEADLIGHT * max(0, n.v)``. Background pixels show the environment (and
the sun's disc). This is what anti-aliasing filters are judged on; it is not a light transport
solution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit, prange

HEADLIGHT = 0.8  # radiance-like scale of the headlight term
#: smallest GGX alpha of the sun's lobe (a mirror's delta lobe would reflect the sun's disc only)
MIN_ROUGHNESS = 0.02
#: material kinds that get the sun's specular lobe
GLOSSY_KINDS = ("plastic", "conductor", "mirror")
#: environment kinds as the kernel sees them
ENV_NONE, ENV_CONSTANT, ENV_SKY, ENV_MAP = range(4)
_ENV_CODES = {"constant": ENV_CONSTANT, "sky": ENV_SKY, "map": ENV_MAP}


def environment_image(environment) -> np.ndarray | None:
    """The equirectangular map of a ``map`` environment as (h, w, 3) float32, else None."""
    if environment is None or environment.kind != "map" or environment.image is None:
        return None
    return environment.image_array()


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


@dataclass(frozen=True)
class SpecularTable:
    """Per-material specular terms: ``f0`` (M, 3) float32 (zero without a lobe), GGX ``alpha``
    (M,) float32 (``max(roughness, MIN_ROUGHNESS)``) and ``metal`` (M,) bool (conductors and
    mirrors: no diffuse term, the environment reflected instead)."""

    f0: np.ndarray
    alpha: np.ndarray
    metal: np.ndarray


def specular_table(materials) -> SpecularTable:
    """The :class:`SpecularTable` of a scene's materials."""
    count = max(len(materials), 1)
    f0 = np.zeros((count, 3), np.float32)
    alpha = np.ones(count, np.float32)
    metal = np.zeros(count, np.bool_)
    for k, m in enumerate(materials):
        if m.kind in GLOSSY_KINDS:
            f0[k] = m.specular
            alpha[k] = max(float(m.roughness), MIN_ROUGHNESS) if m.kind != "mirror" else MIN_ROUGHNESS
            metal[k] = m.kind != "plastic"
    return SpecularTable(f0, alpha, metal)


@njit(cache=True)
def environment_px(dx, dy, dz, kind, radiance, horizon, image, rotation, out):
    """Radiance arriving from the unit direction ``d`` into ``out`` (3,).

    ``sky`` blends linearly from ``horizon`` (at and below the horizon) to ``radiance`` at the
    zenith in the sine of the elevation; ``map`` looks an equirectangular image up (nearest
    texel) with ``u = 0.5 + atan2(d_x, -d_z) / 2 pi + rotation / 360``, ``v = acos(d_y) / pi``
    (row 0 at the zenith); a ``map`` without an image is ``radiance``.
    """
    if kind == ENV_NONE:
        for c in range(3):
            out[c] = 0.0
    elif kind == ENV_SKY:
        t = min(max(dy, 0.0), 1.0)
        for c in range(3):
            out[c] = horizon[c] * (1.0 - t) + radiance[c] * t
    elif kind == ENV_MAP and image.shape[0] > 0:
        h, w = image.shape[0], image.shape[1]
        u = 0.5 + math.atan2(dx, -dz) / (2.0 * math.pi) + rotation / 360.0
        v = math.acos(min(max(dy, -1.0), 1.0)) / math.pi
        col = int(math.floor((u - math.floor(u)) * w)) % w
        row = min(max(int(math.floor(v * h)), 0), h - 1)
        for c in range(3):
            out[c] = image[row, col, c] * radiance[c]
    else:
        for c in range(3):
            out[c] = radiance[c]


@njit(cache=True)
def ggx_lobe(n_l, n_v, n_h, v_h, alpha):
    """``D G / (4 n.v)`` of a GGX microfacet lobe (the BRDF times ``n.l``, without Fresnel).

    GGX distribution ``D = a^2 / (pi ((n.h)^2 (a^2 - 1) + 1)^2)`` and separable Smith masking
    ``G = G1(n.l) G1(n.v)``, ``G1(x) = 2x / (x + sqrt(a^2 + (1 - a^2) x^2))`` (Walter et al.
    2007); zero where the light or the viewer is below the surface.
    """
    if n_l <= 0.0 or n_v <= 0.0:
        return 0.0
    a2 = alpha * alpha
    q = n_h * n_h * (a2 - 1.0) + 1.0
    d = a2 / (math.pi * q * q)
    g_l = 2.0 * n_l / (n_l + math.sqrt(a2 + (1.0 - a2) * n_l * n_l))
    g_v = 2.0 * n_v / (n_v + math.sqrt(a2 + (1.0 - a2) * n_v * n_v))
    return d * g_l * g_v / (4.0 * max(n_v, 1e-4))


@njit(cache=True, parallel=True)
def shade_kernel(material, albedo, normal, direction, emission, f0, alpha, metal, env_kind, env_radiance,
                 env_horizon, env_image, env_rotation, ambient, has_sun, sun_dir, sun_e, sun_radiance, sun_cos_r,
                 headlight, out):
    """Fill ``out`` (H, W, 3) with the shading model of this module (float64 inside)."""
    height, width = material.shape
    for i in prange(height):
        env = np.empty(3)
        for j in range(width):
            dx, dy, dz = direction[i, j, 0], direction[i, j, 1], direction[i, j, 2]
            m = material[i, j]
            if m < 0:
                environment_px(dx, dy, dz, env_kind, env_radiance, env_horizon, env_image, env_rotation, env)
                in_disc = has_sun and dx * sun_dir[0] + dy * sun_dir[1] + dz * sun_dir[2] >= sun_cos_r
                for c in range(3):
                    out[i, j, c] = env[c] + (sun_radiance[c] if in_disc else 0.0)
                continue
            nx, ny, nz = normal[i, j, 0], normal[i, j, 1], normal[i, j, 2]
            n_v = -(nx * dx + ny * dy + nz * dz)
            n_l = nx * sun_dir[0] + ny * sun_dir[1] + nz * sun_dir[2] if has_sun else 0.0
            diffuse = 0.0
            if has_sun:
                diffuse = max(n_l, 0.0) / math.pi
            lobe = 0.0
            v_h = 0.0
            if has_sun and f0[m, 0] + f0[m, 1] + f0[m, 2] > 0.0:
                hx, hy, hz = sun_dir[0] - dx, sun_dir[1] - dy, sun_dir[2] - dz
                inv = 1.0 / max(math.sqrt(hx * hx + hy * hy + hz * hz), 1e-12)
                n_h = min(max((nx * hx + ny * hy + nz * hz) * inv, 0.0), 1.0)
                v_h = min(max(-(dx * hx + dy * hy + dz * hz) * inv, 0.0), 1.0)
                lobe = ggx_lobe(n_l, n_v, n_h, v_h, alpha[m])
            reflect = metal[m] and env_kind != ENV_NONE
            if reflect:
                c_v = min(max(n_v, 0.0), 1.0)
                environment_px(dx + 2.0 * c_v * nx, dy + 2.0 * c_v * ny, dz + 2.0 * c_v * nz, env_kind,
                               env_radiance, env_horizon, env_image, env_rotation, env)
                schlick_v = (1.0 - c_v) ** 5
            schlick_h = (1.0 - v_h) ** 5
            for c in range(3):
                if reflect:
                    value = (f0[m, c] + (1.0 - f0[m, c]) * schlick_v) * env[c]
                else:
                    light = ambient[c] + sun_e[c] * diffuse
                    if headlight:
                        light += HEADLIGHT * max(n_v, 0.0)
                    value = albedo[i, j, c] * light
                if lobe > 0.0:
                    value += (f0[m, c] + (1.0 - f0[m, c]) * schlick_h) * lobe * sun_e[c]
                out[i, j, c] = value + emission[m, c]


def shade(scene, material: np.ndarray, albedo: np.ndarray, normal: np.ndarray, directions: np.ndarray,
          emission: np.ndarray, specular: SpecularTable, env_image: np.ndarray | None) -> np.ndarray:
    """Colour (H, W, 3) float32 of the shading model described in this module.

    Parameters
    ----------
    scene : harness.Scene
    material : ndarray (H, W) int32
        Material index per pixel, -1 for background.
    albedo, normal : ndarray (H, W, 3) float32
        Textured albedo and unit shading normal (ignored on background).
    directions : ndarray (H, W, 3) float32
        Unit primary-ray directions.
    emission : ndarray (M, 3) float32
        Emitted radiance per material.
    specular : SpecularTable
        :func:`specular_table` of the scene's materials.
    env_image : ndarray or None
        The environment map, from :func:`environment_image`.
    """
    env = scene.environment
    sun = scene.sun
    env_kind = ENV_NONE if env is None else _ENV_CODES[env.kind]
    image = env_image if env_image is not None else np.zeros((0, 0, 3), np.float32)
    zeros = np.zeros(3)
    out = np.empty(material.shape + (3,), np.float32)
    shade_kernel(material, albedo, normal, directions, emission, specular.f0, specular.alpha, specular.metal,
                 env_kind, zeros if env is None else np.asarray(env.radiance, np.float64),
                 zeros if env is None else np.asarray(env.horizon, np.float64), image,
                 0.0 if env is None else float(env.rotation),
                 ambient_radiance(env, env_image).astype(np.float64), sun is not None,
                 zeros if sun is None else np.asarray(sun.direction, np.float64),
                 zeros if sun is None else sun_irradiance(sun).astype(np.float64),
                 zeros if sun is None else np.asarray(sun.radiance, np.float64),
                 1.0 if sun is None else float(np.cos(np.radians(sun.angular_radius))),
                 sun is None and env is None, out)
    return out
