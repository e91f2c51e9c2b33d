"""4x4 affine transforms for building scenes: ``from harness import rotation, translation``.

Column vectors: a point ``p`` moves to ``(M @ [p, 1])[:3]``, and ``A @ B`` applies ``B`` first,
as :attr:`harness.SceneObject.transforms` and :meth:`harness.Scene.triangles` read them. Every
function returns a new float64 array.
"""

from __future__ import annotations

import numpy as np


def translation(offset) -> np.ndarray:
    """4x4 translation by ``offset``.

    Parameters
    ----------
    offset : array-like (3,)

    Returns
    -------
    ndarray (4, 4) float64
    """
    m = np.eye(4)
    m[:3, 3] = offset
    return m


def rotation(axis, degrees: float) -> np.ndarray:
    """4x4 rotation by ``degrees`` about ``axis`` through the origin (Rodrigues' formula).

    Counter-clockwise seen from the tip of ``axis`` (right-handed).

    Parameters
    ----------
    axis : array-like (3,)
        Any length: it is normalised; a zero axis gives the identity.
    degrees : float

    Returns
    -------
    ndarray (4, 4) float64
        ``I + sin(t) K + (1 - cos(t)) K^2`` in the upper 3x3 block, ``K`` the cross-product
        matrix of the unit axis.
    """
    a = np.asarray(axis, float)
    a = a / max(np.linalg.norm(a), 1e-12)
    t = np.radians(degrees)
    k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    m = np.eye(4)
    m[:3, :3] = np.eye(3) + np.sin(t) * k + (1.0 - np.cos(t)) * (k @ k)
    return m


__all__ = ["rotation", "translation"]
