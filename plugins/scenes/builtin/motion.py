"""Camera paths and rigid animations shared by the built-in sequences.

Everything here returns plain arrays per frame: camera eye/target rows for
:class:`harness.CameraPath` and (F, 4, 4) object-to-world matrices for
:class:`harness.SceneObject`'s ``transforms``.
"""

from __future__ import annotations

import numpy as np

from harness import rotation, translation


def ease(frames: int) -> np.ndarray:
    """Parameters in [0, 1] for ``frames`` frames, smooth at both ends (smoothstep); (F,)."""
    s = np.linspace(0.0, 1.0, frames)
    return s * s * (3.0 - 2.0 * s)


def along(waypoints, frames: int) -> np.ndarray:
    """Points (F, 3) moving through ``waypoints`` (K, 3) at constant speed per segment, eased overall.

    The path is piecewise linear through the waypoints (K >= 2) and the parameter is eased, so a
    camera starts and stops gently; consecutive frames never coincide.
    """
    pts = np.asarray(waypoints, np.float64)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    s = ease(frames) * cum[-1]
    return np.stack([np.interp(s, cum, pts[:, k]) for k in range(3)], axis=1)


def rolling(start, end, radius: float, frames: int, axis_up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Transforms (F, 4, 4) of a ball of ``radius`` rolling without slipping from ``start`` to ``end``.

    ``start`` and ``end`` are the ball's centre positions; the ball turns about the horizontal
    axis perpendicular to its path by ``distance / radius`` radians (so a texture or a marked
    ball shows the rotation that its motion vectors must carry).
    """
    a, b = np.asarray(start, np.float64), np.asarray(end, np.float64)
    path = b - a
    axis = np.cross(np.asarray(axis_up, np.float64), path)
    axis = axis / max(np.linalg.norm(axis), 1e-12)
    out = []
    for s in np.linspace(0.0, 1.0, frames):
        angle = np.degrees(s * np.linalg.norm(path) / radius)
        out.append(translation(a + s * path) @ rotation(axis, angle))
    return np.stack(out)


def swinging(pivot, axis, amplitude: float, periods: float, frames: int, rest=None) -> np.ndarray:
    """Transforms (F, 4, 4) of a pendulum-like swing about ``axis`` through ``pivot``.

    The angle is ``amplitude * sin(2 pi periods t)`` degrees for ``t`` in [0, 1]; ``rest`` (4x4,
    default identity) places the object before the swing.
    """
    rest = np.eye(4) if rest is None else np.asarray(rest, np.float64)
    p = np.asarray(pivot, np.float64)
    out = []
    for t in np.linspace(0.0, 1.0, frames):
        angle = amplitude * np.sin(2.0 * np.pi * periods * t)
        out.append(translation(p) @ rotation(axis, angle) @ translation(-p) @ rest)
    return np.stack(out)
