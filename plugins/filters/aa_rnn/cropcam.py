"""Cameras that see a crop of a larger frame, rolled, moving: how the training sequences are cut.

The paper cuts its training sequences out of large frames and rotates them. Rendering a whole
large frame to keep a small piece of it would waste most of the work, so a crop is rendered
directly: a pinhole camera aimed at the crop's centre with the field of view that gives the
crop's pixels the angular size they have in the large frame (so thin geometry and minified
textures are as thin and as minified as in that frame), rolled by a random angle about its
viewing direction. Over the sequence the eye moves at a constant velocity and the view pans at
a constant rate (in pixels per frame of the crop), or stays still.
"""

from __future__ import annotations

import numpy as np

from harness import CameraPath

#: heights (pixels) of the large frames that crops are cut from
FRAME_HEIGHTS = (360, 540, 720, 1080)
#: aspect ratio of those frames
ASPECT = 16.0 / 9.0


def _unit(v) -> np.ndarray:
    v = np.asarray(v, np.float64)
    return v / max(float(np.linalg.norm(v)), 1e-12)


def _basis(forward: np.ndarray, up) -> tuple[np.ndarray, np.ndarray]:
    right = np.cross(forward, np.asarray(up, np.float64))
    if np.linalg.norm(right) < 1e-9:
        right = np.cross(forward, np.array([0.0, 0.0, 1.0]))
    right = _unit(right)
    return right, np.cross(right, forward)


def crop_camera(rng: np.random.Generator, base: CameraPath, size: int, frames: int, first: int, speed: float,
                pan: float) -> tuple[CameraPath, dict]:
    """A camera seeing a ``size`` x ``size`` crop of the frame of a base camera, rolled and moving.

    Parameters
    ----------
    rng : numpy.random.Generator
        Draws the large frame's height, the crop's place, the roll and the directions of motion.
    base : harness.CameraPath
        Its frame 0 is the large frame (eye, target, up, vertical field of view, clip distances).
    size : int
        Side of the crop, pixels.
    frames : int
        Frames of the camera path (``first`` of them before the sequence starts).
    first : int
        The frame at which the eye is at ``eye``; the path extends backwards before it.
    speed : float
        Distance the eye moves per frame (scene units; 0: still).
    pan : float
        Pan rate, pixels of the crop per frame (0: none).

    Returns
    -------
    (CameraPath, dict)
        The camera and what was drawn (``frame_height``, ``crop_centre`` in pixels from the large
        frame's centre, ``roll_degrees``, ``fov``).
    """
    height = int(rng.choice(FRAME_HEIGHTS))
    width = height * ASPECT
    half = np.tan(np.radians(base.fov) / 2.0)
    eye = base.eye(0)
    right, upv, forward = base.basis(0)
    cx = float(rng.uniform(-(width - size) / 2.0, (width - size) / 2.0))
    cy = float(rng.uniform(-(height - size) / 2.0, (height - size) / 2.0))
    # pixel offsets -> directions: one pixel of the large frame spans 2 tan(fov/2) / height at unit depth
    scale = 2.0 * half / height
    direction = _unit(forward + cx * scale * right - cy * scale * upv)
    crop_fov = float(np.degrees(2.0 * np.arctan(half * size / height)))
    c_right, c_up = _basis(direction, upv)
    roll = float(rng.uniform(0.0, 2.0 * np.pi))
    rolled_up = np.cos(roll) * c_up + np.sin(roll) * c_right
    velocity = _unit(rng.normal(0.0, 1.0, 3)) * speed
    pan_dir = _unit(rng.normal(0.0, 1.0, 2))
    pan_step = pan * 2.0 * np.tan(np.radians(crop_fov) / 2.0) / size
    s = (np.arange(frames, dtype=np.float64) - first)[:, None]
    eyes = eye + s * velocity
    looks = direction + s * pan_step * (pan_dir[0] * c_right + pan_dir[1] * c_up)
    looks /= np.linalg.norm(looks, axis=1, keepdims=True)
    camera = CameraPath(positions=eyes, targets=eyes + looks, up=tuple(float(v) for v in rolled_up), fov=crop_fov,
                        near=base.near, far=base.far)
    drawn = {"frame_height": height, "crop_centre": [cx, cy], "roll_degrees": float(np.degrees(roll)),
             "fov": crop_fov}
    return camera, drawn
