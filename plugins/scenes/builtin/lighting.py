"""Daylight shared by the outdoor built-in scenes: a sun of given ground irradiance and a sky."""

from __future__ import annotations

import numpy as np

from harness import Environment, Sun


def sun(direction, irradiance: float, angular_radius: float, tint=(1.0, 0.95, 0.88)) -> Sun:
    """A :class:`harness.Sun` whose disc delivers ``irradiance`` (W/m^2-like units) at normal incidence.

    The disc radiance is ``irradiance / solid_angle`` with ``solid_angle = 2 pi (1 - cos r)``.
    """
    solid_angle = 2.0 * np.pi * (1.0 - np.cos(np.radians(angular_radius)))
    radiance = np.asarray(tint, float) * irradiance / solid_angle
    return Sun(direction=tuple(direction), angular_radius=angular_radius, radiance=tuple(radiance))


def sky(scale: float = 1.0) -> Environment:
    """A blue-to-hazy gradient sky (zenith to horizon)."""
    return Environment(kind="sky", radiance=(0.22 * scale, 0.38 * scale, 0.75 * scale),
                       horizon=(0.75 * scale, 0.8 * scale, 0.85 * scale))
