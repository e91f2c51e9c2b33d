"""The white-furnace validation scene: an analytic answer for every pixel.

A closed sphere whose inward-facing surface is diffuse with albedo ``rho`` and emits ``Le``
everywhere; the camera sits inside. Every path sees the same infinite series, so the converged
radiance is ``Le / (1 - rho)`` in every pixel and every colour channel. A renderer that stops
after ``D`` bounces converges to the truncated series ``Le * (1 - rho**(D + 1)) / (1 - rho)``;
both numbers are in the scene's ``params``.
"""

from __future__ import annotations

from harness import CameraPath, Material, Scene, SceneObject

from .assemble import suite_scene
from .primitives import sphere, to_polydata

RHO = 0.5
LE = 0.5
MAX_DEPTH = 32

SPEC = {"name": "furnace", "tags": frozenset({"static", "analytic", "emissive"}), "frames": 1, "resolution": (64, 64)}


def build() -> Scene:
    """Build the ``furnace`` scene (static, one frame)."""
    material = Material("furnace", albedo=(RHO, RHO, RHO), emission=(LE, LE, LE))
    shell = sphere(1.0, 0, rings=24, segments=48).flipped()
    camera = CameraPath(positions=[(0.0, 0.0, 0.0)], targets=[(0.0, 0.0, -1.0)], fov=60.0, near=0.01, far=10.0)
    return suite_scene(
        SPEC,
        objects=[SceneObject("shell", to_polydata(shell))],
        materials=[material],
        camera=camera,
        params={
            "rho": RHO,
            "Le": LE,
            "expected_radiance": LE / (1.0 - RHO),
            "expected_radiance_truncated": LE * (1.0 - RHO ** (MAX_DEPTH + 1)) / (1.0 - RHO),
        },
        max_depth=MAX_DEPTH,
    )
