"""SBF's working layout: padded planar float32 planes made in one pass that also sanitises.

:func:`pack` reads every channel SBF uses once (colour, variance, normal, albedo, depth) and
writes the planes the kernels stream over. The guards cost nothing extra because they sit in
this pass, which reads the data anyway:

* features: NaN -> 0, +-Inf and anything beyond +-1e15 -> +-1e15 (so ``|f_i - f_j|^2`` is
  finite in float32); a non-finite depth is background (normalised depth 2); a zero-length
  normal is just a feature value (0, 0, 0);
* variance: NaN, negative and -0 -> 0 (unknown; estimated where the frame says so), +Inf and
  values above the float32 maximum -> the float32 maximum;
* colour: copied; when its largest magnitude exceeds 2^120 the planes are scaled by a power of
  two (exact) so that the float32 group sums of the kernels cannot overflow, and the output is
  scaled back. NaN colour stays NaN in its own pixel only if the caller passes it (the harness
  repairs or rejects non-finite colour before a filter sees it).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

#: normalised depth given to background pixels (depth not finite): one scene depth behind
BACKGROUND_DEPTH = 2.0
#: bound of a scaled feature: keeps |f_i - f_j|^2 finite in float32 for any input
FEATURE_LIMIT = 1e15
#: colour magnitudes above this are scaled down by a power of two (see module docstring)
COLOUR_LIMIT = 2.0**120
_FLOAT32_MAX = float(np.finfo(np.float32).max)


def feature_scale(sigma: float, var_floor: float) -> float:
    """``1 / sqrt(2 sigma^2 floor)``: a feature scaled by it enters the weight as ``exp(-d^2)``."""
    return float(np.float32(1.0 / np.sqrt(2.0 * sigma * sigma * var_floor)))


def max_depth(frame) -> float:
    """The scene's maximum depth: ``frame.meta.extra["max_depth"]`` or the largest finite depth.

    Returns 1 when neither is a positive finite number.
    """
    given = frame.meta.extra.get("max_depth") if frame.meta.extra else None
    if given is not None and np.isfinite(given) and given > 0:
        return float(given)
    depth = frame["depth"]
    with np.errstate(invalid="ignore"):
        finite = np.abs(np.where(np.isfinite(depth), depth, 0.0))
    zmax = float(finite.max()) if finite.size else 0.0
    return zmax if zmax > 0 else 1.0


@njit(cache=True, inline="always")
def _bounded(x, limit):
    if x != x:  # NaN
        return 0.0
    return min(max(x, -limit), limit)


@njit(parallel=True, cache=True)
def _pack(color, variance, normal, albedo, depth, s_n, s_a, s_z, z_background, c_scale, pad,
          cpad, fpad, inside, var, row_max):
    h, w, _ = color.shape
    limit = FEATURE_LIMIT
    for i in prange(h):
        for j in range(pad):
            inside[i, j] = 0.0
            inside[i, pad + w + j] = 0.0
            for c in range(3):
                cpad[c, i, j] = 0.0
                cpad[c, i, pad + w + j] = 0.0
            for c in range(7):
                fpad[c, i, j] = 0.0
                fpad[c, i, pad + w + j] = 0.0
        peak = 0.0
        for j in range(w):
            q = pad + j
            inside[i, q] = 1.0
            for c in range(3):
                cpad[c, i, q] = color[i, j, c] * c_scale
                fpad[c, i, q] = _bounded(np.float64(normal[i, j, c]) * s_n, limit)
                fpad[3 + c, i, q] = _bounded(np.float64(albedo[i, j, c]) * s_a, limit)
                v = np.float64(variance[i, j, c])
                v = v if v > 0.0 else 0.0  # NaN, negative and -0 -> 0
                v = min(v, _FLOAT32_MAX)
                var[i, j, c] = v * c_scale * c_scale
                peak = max(peak, v)
            z = np.float64(depth[i, j])
            if z - z != 0.0:  # NaN or +-Inf: background
                fpad[6, i, q] = z_background
            else:
                fpad[6, i, q] = _bounded(z * s_z, limit)
        row_max[i] = peak


def colour_scale(color: np.ndarray) -> float:
    """1, or the power of two that brings the largest finite colour magnitude under 2^120."""
    with np.errstate(invalid="ignore"):
        peak = float(np.nanmax(np.abs(color), initial=0.0)) if color.size else 0.0
    if not math.isfinite(peak):
        peak = _FLOAT32_MAX
    if peak <= COLOUR_LIMIT:
        return 1.0
    return 2.0 ** (120 - math.ceil(math.log2(peak)))


def pack(frame, sigmas, var_floor: float, pad: int, work: dict) -> dict:
    """The padded planes of ``frame`` (reused from ``work`` when the shape is unchanged).

    Parameters
    ----------
    frame : Frame
        With ``color``, ``variance``, ``normal``, ``albedo``, ``depth``.
    sigmas : (float, float, float)
        Normal, albedo and depth bandwidths; depth is divided by :func:`max_depth` first.
    var_floor : float
        Floor of the summed feature variance (the whole denominator: noise-free G-buffer).
    pad : int
        Columns of padding on each side.
    work : dict
        Scratch kept by the caller between calls.

    Returns
    -------
    dict
        ``cpad`` (3, H, W + 2 pad), ``fpad`` (7, H, W + 2 pad), ``inside`` (H, W + 2 pad),
        ``var`` (H, W, 3) sanitised variance (scaled like the colour), ``scale`` (the colour
        scale), ``any_variance`` (whether any variance is > 0).
    """
    h, w = frame.shape
    wp = w + 2 * pad
    planes = {
        "cpad": ((3, h, wp), np.float32),
        "fpad": ((7, h, wp), np.float32),
        "inside": ((h, wp), np.float32),
        "valid": ((h, wp), np.float32),
        "var": ((h, w, 3), np.float32),
        "row_max": ((h,), np.float64),
    }
    for name, (shape, dtype) in planes.items():
        if name not in work or work[name].shape != shape:
            work[name] = np.empty(shape, dtype)
    color = frame["color"]
    scale = colour_scale(color)
    s_n = feature_scale(sigmas[0], var_floor)
    s_a = feature_scale(sigmas[1], var_floor)
    s_z = feature_scale(sigmas[2], var_floor)
    _pack(color, frame["variance"], frame["normal"], frame["albedo"], frame["depth"], s_n, s_a,
          s_z / max_depth(frame), BACKGROUND_DEPTH * s_z, scale, pad,
          work["cpad"], work["fpad"], work["inside"], work["var"], work["row_max"])
    work["scale"] = scale
    work["any_variance"] = bool(work["row_max"].max(initial=0.0) > 0)
    return work


@njit(parallel=True, cache=True)
def mark_noisy(var, pad, valid):
    """``valid[i, pad + j] = 1`` where any channel of ``var[i, j]`` is > 0, else 0 (padding 0).

    A noise-free pixel is already exact: the identity has zero risk there, so it is neither
    filtered nor used to smooth the SURE of its neighbours, and it gets no extra samples.
    """
    h, w, _ = var.shape
    for i in prange(h):
        for j in range(valid.shape[1]):
            valid[i, j] = 0.0
        for j in range(w):
            if var[i, j, 0] > 0 or var[i, j, 1] > 0 or var[i, j, 2] > 0:
                valid[i, pad + j] = 1.0
