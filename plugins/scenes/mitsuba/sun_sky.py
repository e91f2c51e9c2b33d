"""Mitsuba's ``sun``, ``sky`` and ``sunsky`` emitters as the harness's lights, with Mitsuba 3's semantics.

A file's parameters are read as Mitsuba 3's ``sunsky`` reads them (names matched case- and
underscore-insensitively, so Mitsuba 0.6's camelCase names are the same parameters):

============================  ==========================================================
the file                      Mitsuba 3 ``sunsky``
============================  ==========================================================
``sunDirection``              ``sun_direction`` (world); no date/time/location model
``turbidity``                 ``turbidity`` (default 3, clamped to [1, 10])
``albedo``                    ``albedo`` (default 0.3, clamped to [0, 1])
``skyScale``                  ``sky_scale`` (default 1)
``sunScale``                  ``sun_scale`` (default 1)
0.6 ``scale``                 the default of ``sky_scale`` and ``sun_scale``
``sunRadiusScale`` s          ``sun_aperture`` = s x 0.5358 degrees (irradiance kept)
``sun_aperture``              ``sun_aperture`` (degrees, default 0.5358, at least 0.02)
``complex_sun``               ``complex_sun`` (default false)
0.6 ``sky`` / ``sun``         ``sunsky`` with ``sun_scale`` / ``sky_scale`` 0
zenith                        Mitsuba 0.6: +y (``toWorld`` applies after); Mitsuba 3:
                              ``to_world`` times +z
============================  ==========================================================

With the model's coefficients (:func:`.hosek_wilkie.load_tables`, from the installed Mitsuba 3), the
sky is baked into an environment map and the sun is a disc of Mitsuba 3's solar radiance (the
mean over the disc with ``complex_sun``, whose limb darkening a uniform disc cannot hold); without
them, a gradient sky and a white disc, warned with the reason. Either way the warning names the
model used (it is listed in the run's manifest), and :func:`sun_and_sky` returns the Mitsuba 3
parameters (``Scene.params["sunsky"]``), from which ``benchmarks/bench_pathtracer.py`` builds
Mitsuba 3's own emitter.
"""

from __future__ import annotations

import dataclasses
import math
import xml.etree.ElementTree as ET

import numpy as np

from harness import Environment, Sun

from .hosek_wilkie import SUN_APERTURE, Y_UP, SunskyParams, bake_sky, load_tables, sun_disc_radiance
from .xmlscene import find, get_bool, get_color, get_float, transform, vector, warn

KINDS = ("sun", "sky", "sunsky")
#: rows of the baked sky map (its width is twice this): 0.7 degrees per texel; irradiance from it is
#: within 0.05% of the exact integral (docs/pathtracer.md)
SKY_MAP_HEIGHT = 256
#: the smallest sun aperture (degrees): the path tracer's sun cone is at least 0.01 degrees wide
MIN_APERTURE = 0.02
IGNORED = ("stretch", "resolution", "extend", "sampling_weight")
TIME_AND_PLACE = ("year", "month", "day", "hour", "minute", "second", "latitude", "longitude", "timezone")


def sunsky_params(node: ET.Element, file_version: tuple) -> SunskyParams:
    """The Mitsuba 3 ``sunsky`` parameters of a ``sun``/``sky``/``sunsky`` element (see the module's table)."""
    kind = node.get("type")
    matrix = transform(find(node, "to_world"))[:3, :3]
    to_world = matrix if tuple(file_version) >= (3,) else matrix @ np.asarray(Y_UP)
    direction_node = find(node, "sun_direction")
    if direction_node is not None:
        direction = vector(direction_node)
    else:
        given = [n for n in TIME_AND_PLACE if find(node, n) is not None]
        warn(f"{kind}: sun position from date, time and location is not computed ({', '.join(given) or 'defaults'}); "
             "using 45 degrees elevation")
        direction = to_world @ np.array([0.5, 0.5, math.sqrt(0.5)])
    for name in IGNORED:
        if find(node, name) is not None:
            warn(f"{kind}: parameter {name!r} has no Mitsuba 3 counterpart and was ignored")
    scale = get_float(node, "scale", 1.0)
    sky_scale = 0.0 if kind == "sun" else get_float(node, "sky_scale", scale)
    sun_scale = 0.0 if kind == "sky" else get_float(node, "sun_scale", scale)
    aperture = get_float(node, "sun_aperture", None)
    if aperture is None:
        aperture = SUN_APERTURE * get_float(node, "sun_radius_scale", 1.0)
    if not MIN_APERTURE <= aperture <= 179.0:
        warn(f"{kind}: sun aperture {aperture:g} degrees is outside [{MIN_APERTURE:g}, 179] (the path tracer's "
             "smallest sun and Mitsuba 3's largest); clamped")
        aperture = min(max(aperture, MIN_APERTURE), 179.0)
    turbidity = get_float(node, "turbidity", 3.0)
    if not 1.0 <= turbidity <= 10.0:
        warn(f"{kind}: turbidity {turbidity:g} is outside Mitsuba 3's range [1, 10]; clamped")
        turbidity = min(max(turbidity, 1.0), 10.0)
    albedo = np.asarray(get_color(node, "albedo", (0.3, 0.3, 0.3)), float)
    if np.any((albedo < 0.0) | (albedo > 1.0)):
        warn(f"{kind}: ground albedo {tuple(albedo)} is outside [0, 1]; clamped")
    return SunskyParams(sun_direction=tuple(direction), turbidity=turbidity, albedo=tuple(np.clip(albedo, 0.0, 1.0)),
                        sky_scale=max(sky_scale, 0.0), sun_scale=max(sun_scale, 0.0), sun_aperture=aperture,
                        complex_sun=get_bool(node, "complex_sun", False), to_world=to_world)


def sun_and_sky(node: ET.Element, file_version: tuple) -> tuple[Environment | None, Sun | None, dict]:
    """A ``sun``/``sky``/``sunsky`` element as (environment, sun, Mitsuba 3 parameters).

    Returns
    -------
    environment : harness.Environment or None
        The Hosek-Wilkie sky baked into a map (:data:`SKY_MAP_HEIGHT` rows), or the gradient
        approximation when the coefficients cannot be read; None without a sky.
    sun : harness.Sun or None
        A disc of half the aperture; None without a sun.
    record : dict
        ``model`` ("hosek-wilkie" or "gradient") and the :class:`.hosek_wilkie.SunskyParams` fields
        (JSON-ready lists), for ``Scene.params["sunsky"]``.
    """
    kind = node.get("type")
    params = sunsky_params(node, file_version)
    if params.sun_elevation < 0.0:
        warn(f"{kind}: the sun is below the horizon; sky and sun are black (as in Mitsuba 3)")
    tables, reason = load_tables()
    if tables is None:
        env, sun = _gradient(params)
        warn(f"{kind}: Hosek-Wilkie sky and sun approximated by a zenith-to-horizon gradient (scale "
             f"{params.sky_scale:g}) and a white disc of irradiance {params.sun_scale:g}, because the model's "
             f"published coefficients could not be read: {reason}")
        model = "gradient"
    else:
        env, sun = _hosek_wilkie(params, tables)
        parts = [f"Hosek-Wilkie model evaluated from Mitsuba 3's coefficients (turbidity {params.turbidity:g})"]
        if env is not None:
            parts.append(f"the sky baked into a {SKY_MAP_HEIGHT}x{2 * SKY_MAP_HEIGHT} environment map")
        if sun is not None and params.complex_sun:
            parts.append(f"the sun a disc of uniform radiance, the mean of Mitsuba 3's limb-darkened solar radiance "
                         f"(complex_sun) over its {params.sun_aperture:g}-degree aperture (same power)")
        elif sun is not None:
            parts.append(f"the sun a disc of {params.sun_aperture:g} degrees of Mitsuba 3's uniform solar radiance")
        warn(f"{kind}: " + "; ".join(parts))
        model = "hosek-wilkie"
    record = {"model": model}
    for key, value in dataclasses.asdict(params).items():
        record[key] = value if isinstance(value, bool) else np.asarray(value, float).tolist()
    return env, sun, record


def _hosek_wilkie(params: SunskyParams, tables: dict) -> tuple[Environment | None, Sun | None]:
    env = sun = None
    if params.sky_scale > 0.0 and params.sun_elevation >= 0.0:
        env = Environment(kind="map", image=bake_sky(params, tables, SKY_MAP_HEIGHT), radiance=(1.0, 1.0, 1.0))
    if params.sun_scale > 0.0 and params.sun_elevation >= 0.0:
        disc = sun_disc_radiance(params, tables)
        if float(np.max(disc)) > 0.0:
            sun = Sun(direction=params.sun_direction, angular_radius=0.5 * params.sun_aperture, radiance=tuple(disc))
    return env, sun


def _gradient(params: SunskyParams) -> tuple[Environment | None, Sun | None]:
    """The approximation used without the coefficients: a blue gradient sky and a white disc."""
    env = sun = None
    scale = params.sky_scale
    if scale > 0.0:
        env = Environment(kind="sky", radiance=(0.06 * scale, 0.1 * scale, 0.2 * scale),
                          horizon=(0.16 * scale, 0.17 * scale, 0.18 * scale))
    if params.sun_scale > 0.0:
        radius = 0.5 * params.sun_aperture
        solid_angle = 2.0 * math.pi * (1.0 - math.cos(math.radians(radius)))
        sun = Sun(direction=params.sun_direction, angular_radius=radius,
                  radiance=(params.sun_scale / solid_angle,) * 3)
    return env, sun


__all__ = ["KINDS", "SKY_MAP_HEIGHT", "sun_and_sky", "sunsky_params"]
