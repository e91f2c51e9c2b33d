"""Small mesh scenes for the path tracer's tests, built with PyVista and the harness scene model."""

from __future__ import annotations

import numpy as np
import pyvista as pv

from harness import CameraPath, Environment, Material, Scene, SceneObject, Sun


def quad(center, normal, size):
    """A square of side ``size`` facing ``normal``, two triangles."""
    return pv.Plane(center=center, direction=normal, i_size=size, j_size=size).triangulate()


def box_scene(*, size=(24, 24), light_size=0.5, emission=10.0, max_depth=6, spheres=True) -> Scene:
    """A Cornell-like box (white, red, green walls), a square ceiling light, a GGX metal and a
    GGX plastic sphere."""
    mats = [
        Material("white", albedo=0.7),
        Material("red", albedo=(0.7, 0.1, 0.1)),
        Material("green", albedo=(0.1, 0.7, 0.1)),
        Material("light", albedo=0.0, emission=(emission, emission, emission)),
        Material("metal", kind="conductor", roughness=0.25, specular=(0.9, 0.8, 0.6)),
        Material("plastic", kind="plastic", albedo=(0.2, 0.3, 0.8), roughness=0.2),
    ]
    objs = [
        SceneObject("floor", quad((0, 0, 0), (0, 1, 0), 2), 0),
        SceneObject("ceiling", quad((0, 2, 0), (0, -1, 0), 2), 0),
        SceneObject("back", quad((0, 1, -1), (0, 0, 1), 2), 0),
        SceneObject("left", quad((-1, 1, 0), (1, 0, 0), 2), 1),
        SceneObject("right", quad((1, 1, 0), (-1, 0, 0), 2), 2),
        SceneObject("light", quad((0, 1.98, 0), (0, -1, 0), light_size), 3),
    ]
    if spheres:
        objs.append(SceneObject("metal_ball", pv.Sphere(radius=0.35, center=(-0.4, 0.35, -0.2),
                                                        theta_resolution=12, phi_resolution=12), 4))
        objs.append(SceneObject("plastic_ball", pv.Sphere(radius=0.3, center=(0.4, 0.3, 0.2),
                                                          theta_resolution=12, phi_resolution=12), 5))
    cam = CameraPath(positions=[(0, 1, 3.5)], targets=[(0, 1, 0)], fov=40)
    return Scene("pt-box", objects=objs, materials=mats, camera=cam, resolution=size, max_depth=max_depth)


def furnace_scene(rho=0.5, le=0.5, *, size=(16, 16), max_depth=64) -> Scene:
    """The inside of a closed, flat-shaded sphere of albedo ``rho`` emitting ``le``."""
    shell = pv.Sphere(radius=1.0, theta_resolution=16, phi_resolution=12)
    shell.point_data.clear()
    mats = [Material("furnace", albedo=rho, emission=(le, le, le))]
    cam = CameraPath(positions=[(0.0, 0.1, 0.0)], targets=[(0.0, 0.0, -1.0)], fov=70)
    return Scene("pt-furnace", objects=[SceneObject("shell", shell, 0)], materials=mats, camera=cam,
                 resolution=size, max_depth=max_depth)


def sphere_under_sky(*, env=None, sun=None, rho=0.6, size=(16, 16), kind="diffuse") -> Scene:
    """A convex, flat-shaded sphere of albedo ``rho`` lit by an environment and/or a sun."""
    ball = pv.Sphere(radius=1.0, theta_resolution=12, phi_resolution=10)
    ball.point_data.clear()
    mats = [Material("ball", kind=kind, albedo=rho, roughness=0.3, specular=(0.9, 0.9, 0.9))]
    cam = CameraPath(positions=[(0.0, 0.5, 3.0)], targets=[(0.0, 0.0, 0.0)], fov=50)
    return Scene("pt-sky", objects=[SceneObject("ball", ball, 0)], materials=mats, camera=cam,
                 resolution=size, max_depth=8, environment=env, sun=sun)


def env_map(h=16, w=32) -> np.ndarray:
    """A smooth equirectangular map with a bright spot (for importance-sampling tests)."""
    v, u = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
    img = 0.2 + 0.3 * u[..., None] * np.array([1.0, 0.6, 0.3]) + 3.0 * np.exp(
        -((u - 0.3) ** 2 + (v - 0.3) ** 2) / 0.01)[..., None]
    return img.astype(np.float32)


__all__ = ["Environment", "Sun", "box_scene", "env_map", "furnace_scene", "quad", "sphere_under_sky"]
