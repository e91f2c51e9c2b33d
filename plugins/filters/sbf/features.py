"""Guide features of the SBF cross-bilateral filters, scaled so that a weight is exp(-|df|^2)."""

from __future__ import annotations

import numpy as np

#: normalised depth given to background pixels (depth inf): one scene depth behind the farthest
BACKGROUND_DEPTH = 2.0
# bound of a scaled feature: keeps |f_i - f_j|^2 finite in float32 for any finite input
_FEATURE_LIMIT = 1e15


def max_depth(frame) -> float:
    """The scene's maximum depth: ``frame.meta.extra["max_depth"]`` or the largest finite depth.

    Returns 1 when neither is a positive finite number.
    """
    given = frame.meta.extra.get("max_depth") if frame.meta.extra else None
    if given is not None and np.isfinite(given) and given > 0:
        return float(given)
    depth = frame["depth"]
    finite = depth[np.isfinite(depth)]
    zmax = float(np.abs(finite).max()) if finite.size else 0.0
    return zmax if zmax > 0 else 1.0


def guide_features(frame, sigma_normal: float, sigma_albedo: float, sigma_depth: float,
                   var_floor: float) -> np.ndarray:
    """Planar guide features, scaled by ``1 / sqrt(2 sigma_k^2 max(var_i + var_j, floor))``.

    The G-buffer is noise-free (feature variance 0), so ``max(var_i + var_j, floor) = floor``
    and the SBF feature term ``sum_k (f_ik - f_jk)^2 / (2 sigma_k^2 floor)`` becomes the squared
    Euclidean distance of the scaled features.

    Parameters
    ----------
    frame : Frame
        With ``normal`` (H, W, 3), ``albedo`` (H, W, 3) and ``depth`` (H, W).
    sigma_normal, sigma_albedo, sigma_depth : float
        Feature bandwidths; depth is first divided by :func:`max_depth`, background depth
        (non-finite) becomes :data:`BACKGROUND_DEPTH`.
    var_floor : float
        Lower bound of the summed feature variance (0.01 in the paper).

    Returns
    -------
    ndarray (7, H, W) float32
        Normal x, y, z, albedo r, g, b, depth; finite and bounded by 1e15.
    """
    h, w = frame.shape
    planes = np.empty((7, h, w), np.float32)
    for c in range(3):
        np.multiply(frame["normal"][..., c], _scale(sigma_normal, var_floor), out=planes[c])
        np.multiply(frame["albedo"][..., c], _scale(sigma_albedo, var_floor), out=planes[3 + c])
    depth = frame["depth"]
    z_scale = float(_scale(sigma_depth, var_floor))
    with np.errstate(over="ignore", invalid="ignore"):
        z = depth.astype(np.float64) * (z_scale / max_depth(frame))
    planes[6] = np.where(np.isfinite(depth), z, BACKGROUND_DEPTH * z_scale)
    np.nan_to_num(planes, copy=False, nan=0.0, posinf=_FEATURE_LIMIT, neginf=-_FEATURE_LIMIT)
    return np.clip(planes, -_FEATURE_LIMIT, _FEATURE_LIMIT, out=planes)


def _scale(sigma: float, var_floor: float) -> np.float32:
    return np.float32(1.0 / np.sqrt(2.0 * sigma * sigma * var_floor))


def noisy_mask(variance: np.ndarray) -> np.ndarray:
    """Pixels with noise (any channel of the planar (3, H, W) variance > 0), uint8 (H, W).

    A noise-free pixel is already exact: the identity has zero risk there, so it is neither
    filtered nor used to smooth the SURE of its neighbours, and it gets no extra samples.
    """
    return np.ascontiguousarray((variance > 0).any(axis=0), dtype=np.uint8)
