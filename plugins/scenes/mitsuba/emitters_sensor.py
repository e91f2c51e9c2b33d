"""Mitsuba emitters (environment, sun, sky, directional, point, spot) and the perspective sensor."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from harness import CameraPath, Environment, Sun, read_texture

from .files import scene_file
from .xmlscene import find, get_color, get_float, get_int, get_string, transform, vector, warn

# The path tracer has no delta lights: Mitsuba's directional light becomes a disc this small
# (degrees) of the same irradiance, its point light an emitting sphere of this radius (a fraction
# of the scene's bounding-box diagonal) of the same intensity.
DIRECTIONAL_RADIUS = 0.05
POINT_RADIUS = 1e-3


def environment_and_sun(node: ET.Element, folder: Path) -> tuple[Environment | None, Sun | None]:
    """An ``<emitter>`` that is not attached to a shape as (environment, sun); either may be None.

    The sun and sky kinds are :func:`sun_and_sky`'s.
    """
    kind = node.get("type")
    if kind == "constant":
        radiance = get_color(node, "radiance", (1.0, 1.0, 1.0), illuminant=True)
        return Environment(kind="constant", radiance=radiance), None
    if kind == "envmap":
        matrix = transform(find(node, "toWorld"))
        scale = get_float(node, "scale", 1.0)
        image = read_texture(scene_file(node, folder))
        image = envmap_to_harness(image, matrix[:3, :3])
        return Environment(kind="map", image=image, radiance=(scale, scale, scale)), None
    if kind == "directional":
        return None, directional(node)
    warn(f"emitter type {kind!r} is not supported and was skipped")
    return None, None


def directional(node: ET.Element) -> Sun:
    """Mitsuba's ``directional`` emitter as a disc of :data:`DIRECTIONAL_RADIUS` degrees.

    The light travels along ``direction`` (or ``toWorld``'s +z); the disc lies the other way and
    its radiance ``E / (pi sin^2 r)`` gives the same ``irradiance`` E at normal incidence.
    """
    irradiance = get_color(node, "irradiance", (1.0, 1.0, 1.0), illuminant=True)
    direction_node = find(node, "direction")
    if direction_node is not None:
        travel = vector(direction_node)
    else:
        travel = transform(find(node, "toWorld"))[:3, :3] @ np.array([0.0, 0.0, 1.0])
    disc = np.pi * np.sin(np.radians(DIRECTIONAL_RADIUS)) ** 2
    warn(f"directional light approximated by a disc of {DIRECTIONAL_RADIUS:g} degrees of the same irradiance "
         "(the path tracer has no delta lights)")
    return Sun(direction=tuple(-np.asarray(travel, float)), angular_radius=DIRECTIONAL_RADIUS,
               radiance=tuple(e / disc for e in irradiance))


def point_light(node: ET.Element, diagonal: float) -> tuple[np.ndarray, float, tuple]:
    """Mitsuba's ``point`` emitter as (centre, radius, radiance) of an emitting sphere.

    The sphere's radius is :data:`POINT_RADIUS` times the scene's ``diagonal``; radiance
    ``I / (pi r^2)`` makes its intensity (the sphere's projected area ``pi r^2`` times that
    radiance) Mitsuba's ``intensity`` I in every direction.
    """
    intensity = get_color(node, "intensity", (1.0, 1.0, 1.0), illuminant=True)
    position = find(node, "position")
    centre = vector(position) if position is not None else transform(find(node, "toWorld"))[:3, 3]
    radius = POINT_RADIUS * max(diagonal, 1e-6)
    warn(f"point light approximated by an emitting sphere of radius {radius:.3g} of the same intensity (the path "
         "tracer has no delta lights)")
    return np.asarray(centre, float), radius, tuple(i / (np.pi * radius * radius) for i in intensity)


def spot_light(node: ET.Element) -> dict:
    """Mitsuba's ``spot`` emitter as a delta light (an entry of ``Scene.params["delta_lights"]``).

    The light sits at ``toWorld``'s origin and shines along its +z; a direction ``d`` from it has the
    local direction ``normalize(toWorld^-1 d)`` and the intensity ``intensity f(theta)`` with
    Mitsuba's falloff ``f`` (``cutoffAngle`` default 20 degrees, ``beamWidth`` default 3/4 of it).
    Renderers that read ``delta_lights`` (the path tracer) render it exactly.
    """
    matrix = transform(find(node, "toWorld"))
    intensity = get_color(node, "intensity", (1.0, 1.0, 1.0), illuminant=True)
    cutoff = get_float(node, "cutoffAngle", 20.0)
    beam = get_float(node, "beamWidth", cutoff * 3.0 / 4.0)
    if find(node, "texture") is not None:
        warn("spot light: the projected texture is not supported (its intensity and falloff are kept)")
    linear = matrix[:3, :3]
    to_local = np.linalg.inv(linear) if abs(np.linalg.det(linear)) > 1e-12 else np.eye(3)
    return {"type": "spot", "position": [float(v) for v in matrix[:3, 3]],
            "to_local": [[float(v) for v in row] for row in to_local],
            "intensity": [float(v) for v in intensity], "cutoff_angle": float(cutoff),
            "beam_width": float(min(beam, cutoff))}


def camera(node: ET.Element) -> tuple[CameraPath, tuple[int, int]]:
    """The perspective ``<sensor>`` as a one-frame :class:`harness.CameraPath` and its film size.

    Mitsuba's camera looks along +z of ``toWorld`` with +y up; ``fov`` is measured along
    ``fovAxis`` (default ``x``) and converted to the vertical field of view.
    """
    kind = node.get("type")
    if kind not in ("perspective", "thinlens"):
        warn(f"sensor type {kind!r} approximated by a perspective pinhole")
    elif kind == "thinlens":
        warn("thinlens sensor approximated by a pinhole (no depth of field)")
    film = node.find("film")
    width = get_int(film, "width", 768) if film is not None else 768
    height = get_int(film, "height", 576) if film is not None else 576
    matrix = transform(find(node, "toWorld"))
    if np.linalg.det(matrix[:3, :3]) < 0:
        warn("sensor toWorld mirrors the image; the camera renders it unmirrored")
    eye = matrix[:3, 3]
    forward = matrix[:3, :3] @ np.array([0.0, 0.0, 1.0])
    up = matrix[:3, :3] @ np.array([0.0, 1.0, 0.0])
    fov = get_float(node, "fov", None)
    axis = (get_string(node, "fovAxis", "x") or "x").lower()
    if fov is None:
        focal = get_string(node, "focalLength", "50mm")
        mm = float(focal.replace("mm", ""))
        fov, axis = float(np.degrees(2 * np.arctan(36.0 / (2 * mm)))), "x"
        warn(f"focalLength {focal} converted to a horizontal fov of {fov:.3g} degrees (35 mm film)")
    tan_half = np.tan(np.radians(fov) / 2)
    aspect = width / height
    if axis == "smaller":
        axis = "x" if width < height else "y"
    elif axis == "larger":
        axis = "x" if width >= height else "y"
    if axis == "x":
        tan_half /= aspect
    elif axis == "diagonal":
        tan_half /= np.hypot(aspect, 1.0)
    vertical = float(np.degrees(2 * np.arctan(tan_half)))
    near = get_float(node, "nearClip", 0.01)
    far = get_float(node, "farClip", 10000.0)
    path = CameraPath(positions=[eye], targets=[eye + forward], up=tuple(up / np.linalg.norm(up)), fov=vertical,
                      near=min(near, 0.05), far=far)
    return path, (width, height)


def envmap_to_harness(image: np.ndarray, to_world: np.ndarray) -> np.ndarray:
    """Resample a Mitsuba ``envmap`` image with its ``toWorld`` rotation into the harness's map convention.

    Mitsuba looks up world direction ``d`` at ``v = toWorld^-1 d``, ``u = atan2(v_x, -v_z) / (2 pi)``
    (mod 1), ``v = acos(v_y) / pi``, bilinearly (texel centres at half-integers, u wrapping). The
    harness map (no rotation) has ``u = 0.5 + atan2(d_x, -d_z) / (2 pi)``, ``v = acos(d_y) / pi``.
    Each texel of the result holds Mitsuba's radiance in the direction of its centre, at the same
    resolution as the source, so any rotation (tilts included) is exact up to this resampling.
    """
    img = np.asarray(image, np.float32)[..., :3]
    h, w = img.shape[:2]
    theta = (np.arange(h) + 0.5) / h * np.pi
    phi = ((np.arange(w) + 0.5) / w - 0.5) * 2.0 * np.pi
    st = np.sin(theta)[:, None]
    d = np.stack([st * np.sin(phi)[None, :], np.broadcast_to(np.cos(theta)[:, None], (h, w)),
                  -st * np.cos(phi)[None, :]], axis=-1)
    local = d @ np.linalg.inv(np.asarray(to_world, float)).T
    local /= np.maximum(np.linalg.norm(local, axis=-1, keepdims=True), 1e-12)
    u = np.mod(np.arctan2(local[..., 0], -local[..., 2]) / (2.0 * np.pi), 1.0)
    v = np.arccos(np.clip(local[..., 1], -1.0, 1.0)) / np.pi
    x = u * w - 0.5
    y = np.clip(v * h - 0.5, 0.0, h - 1.0)
    x0 = np.floor(x).astype(int)
    y0 = np.minimum(np.floor(y).astype(int), h - 2) if h > 1 else np.zeros_like(x0)
    fx = (x - x0)[..., None]
    fy = (y - y0)[..., None] if h > 1 else np.zeros_like(fx)
    x0 %= w
    x1 = (x0 + 1) % w
    y1 = np.minimum(y0 + 1, h - 1)
    out = ((1 - fy) * ((1 - fx) * img[y0, x0] + fx * img[y0, x1]) + fy * ((1 - fx) * img[y1, x0] + fx * img[y1, x1]))
    return np.ascontiguousarray(out, np.float32)
