"""The harness camera of a frame as a Mitsuba perspective sensor.

``scene.camera`` (:class:`harness.CameraPath`) gives each frame's eye, target, up vector and
vertical field of view; the sensor is Mitsuba's ``perspective`` with ``fov_axis="y"`` and
``look_at(eye, target, up)`` (Mitsuba's camera looks along +z with +x to the left, and its image
x grows to the right, so the image is the harness's). A ray through film position
``((j + 0.5) / W, (i + 0.5) / H)`` is the harness ray of pixel (i, j): image coordinates
``(x, y) = (j, i)`` at the pixel centre, y down (``tests/test_mitsuba_renderer.py`` checks the
directions against :meth:`harness.CameraPath.primary_rays`). The path tracer clips nothing, so
the near plane is :data:`NEAR` and the far plane :data:`FAR` in scene units.
"""

from __future__ import annotations

import numpy as np

NEAR = 1e-4
FAR = 1e8


def view(camera, frame: int, width: int, height: int) -> dict:
    """What a sensor needs of ``camera`` at ``frame`` (plain floats; eye and forward for the G-buffer)."""
    right, up, forward = camera.basis(frame)
    eye = np.asarray(camera.eye(frame), np.float64)
    return {"eye": [float(v) for v in eye], "target": [float(v) for v in eye + forward],
            "up": [float(v) for v in up], "forward": [float(v) for v in forward], "fov": camera.fov_at(frame),
            "width": int(width), "height": int(height), "near": NEAR, "far": FAR}


def sensor(mi, v: dict, sampler: dict | None = None):
    """Mitsuba's perspective sensor of view ``v`` (a box pixel filter; ``sampler`` default independent)."""
    return mi.load_dict({
        "type": "perspective", "fov": v["fov"], "fov_axis": "y", "near_clip": v["near"], "far_clip": v["far"],
        "to_world": mi.ScalarTransform4f().look_at(origin=v["eye"], target=v["target"], up=v["up"]),
        "film": {"type": "hdrfilm", "width": v["width"], "height": v["height"], "pixel_format": "rgb",
                 "rfilter": {"type": "box"}},
        "sampler": sampler or {"type": "independent", "sample_count": 1},
    })
