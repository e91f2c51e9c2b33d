"""Stand-ins for guide channels a capture lacks: what a filter's degraded mode reads instead.

Captured frames often hold colour, albedo and normal only (what an OIDN user has). A filter that
can run on fewer guides declares the others ``optional`` (:class:`harness.FilterSpec`) and fills
what is missing with these stand-ins; the row's ``guides`` column then names the guides it had.
(A missing ``variance`` is the filter's own business: SBF and LBF estimate it from the image.)

* :func:`pinhole_position`: a camera-space position from depth (or unit depth) and the pixel's
  place, for an unknown camera of a 53 degree horizontal field of view: differences between
  neighbours are right in proportion, not in scene units.
* :func:`constant_depth`, :func:`zero_motion`, :func:`one_object`: neutral values (every
  depth stop passes, no motion, one object).
"""

from __future__ import annotations

import numpy as np


def pinhole_position(shape, depth: np.ndarray | None = None) -> np.ndarray:
    """Camera-space positions (H, W, 3) float32 of an unknown pinhole camera (53 degree horizontal
    field of view) from ``depth`` (H, W), or at depth 1 where None; non-finite depth counts as 1."""
    h, w = shape
    z = np.ones((h, w)) if depth is None else np.asarray(depth, np.float64)
    z = np.where(np.isfinite(z), z, 1.0)
    x = (np.arange(w) + 0.5 - 0.5 * w) / w
    y = (np.arange(h) + 0.5 - 0.5 * h) / w
    return np.stack([x[None, :] * z, y[:, None] * z, z], axis=-1).astype(np.float32)


def constant_depth(shape) -> np.ndarray:
    """Depth 1 at every pixel (H, W) float32: depth edge stops pass everywhere."""
    return np.ones(shape, np.float32)


def zero_motion(shape) -> np.ndarray:
    """No motion (H, W, 2) float32."""
    return np.zeros((*shape, 2), np.float32)


def one_object(shape) -> np.ndarray:
    """Object id 0 at every pixel (H, W) int32."""
    return np.zeros(shape, np.int32)
