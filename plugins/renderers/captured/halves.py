"""The colour and its variance from two half-buffers (two independent renders of a frame).

Renders ``a`` and ``b`` of a frame, each with half of its samples, are independent with the same
distribution, so per pixel and channel their mean is the colour at the full sample count and

    E[(a - b)^2] = 2 Var(half),   Var(mean) = Var(half) / 2,   so   E[(a - b)^2 / 4] = Var(mean):

``(a - b)^2 / 4`` is an unbiased estimate of the variance of the colour's mean (the harness's
``variance``) for any distribution of the samples. It has one degree of freedom (for Gaussian
noise its relative standard error is sqrt(2), 141%), so the served channel averages it over a
feature-aware window (:func:`half_variance`): the 5x5 pixels around each pixel, weighted by how
alike their normal, albedo and depth are. The weights do not depend on the colour, so the average
stays unbiased where the true variance is constant over the pixels it weights; see
``docs/captured.md`` for the measurements behind the window.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from harness import kernels

#: radius of the averaging window (5x5)
RADIUS = 2
#: weight exp(-(1 - n.n') / SIGMA_NORMAL) of a neighbour's normal n' (unit normals)
SIGMA_NORMAL = 0.8
#: weight exp(-|albedo - albedo'|^2 / SIGMA_ALBEDO^2)
SIGMA_ALBEDO = 0.1
#: weight exp(-((z - z') / z)^2 / SIGMA_DEPTH^2) of a neighbour's view depth z'
SIGMA_DEPTH = 0.05
#: largest float32, the ceiling of a served variance
FLOAT32_MAX = float(np.finfo(np.float32).max)
#: relative tolerance of ``color == (a + b) / 2``: 8 float32 units in the last place of max(|a|, |b|)
MEAN_RTOL = 2.0 ** -20
#: absolute tolerance of that check (the smallest normal float32)
MEAN_ATOL = float(np.finfo(np.float32).tiny)


def mean_of_halves(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The colour of the full sample count: ``(a + b) / 2`` summed in float64, stored float32."""
    return ((a.astype(np.float64) + b.astype(np.float64)) * 0.5).astype(np.float32)


def mean_mismatch(color: np.ndarray, a: np.ndarray, b: np.ndarray) -> str:
    """Why ``color`` is not the mean of ``a`` and ``b`` within float32 rounding, or ``""`` when it is.

    Pixels where the mean is not finite must hold a non-finite colour too (and the reverse).
    """
    a64, b64, c64 = (x.astype(np.float64) for x in (a, b, color))
    mean = (a64 + b64) * 0.5
    finite = np.isfinite(mean) & np.isfinite(c64)
    with np.errstate(invalid="ignore"):
        scale = np.maximum(np.abs(a64), np.abs(b64))
        diff = np.where(finite, np.abs(c64 - mean), 0.0)
        bad = (finite & (diff > MEAN_RTOL * scale + MEAN_ATOL)) | (np.isfinite(mean) != np.isfinite(c64))
    count = int(np.count_nonzero(bad))
    if not count:
        return ""
    worst = np.unravel_index(int(np.argmax(np.where(bad, np.where(finite, diff, np.inf), -1.0))), bad.shape)
    y, x = int(worst[0]), int(worst[1])
    return (f"the colour is not the mean of the two half-buffers in {count} value(s) (e.g. pixel x={x} y={y}: "
            f"colour {color[worst]!r}, mean {mean[worst]!r}); drop 'color' from the sidecar to use their mean")


def pair_variance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(a - b)^2 / 4`` per pixel and channel, float64: the one-pair estimate of Var(mean)."""
    d = a.astype(np.float64) - b.astype(np.float64)
    return d * d * 0.25


def half_variance(a: np.ndarray, b: np.ndarray, guides: dict | None = None) -> np.ndarray:
    """The served ``variance`` (H, W, 3) float32: :func:`pair_variance` averaged over the window.

    Parameters
    ----------
    a, b : ndarray (H, W, 3)
        The two half-buffers (linear sRGB).
    guides : dict, optional
        ``normal`` (H, W, 3), ``albedo`` (H, W, 3), ``depth`` (H, W), whichever the capture has
        (None or a missing key: not used); without any the window is a plain 5x5 box.

    Returns
    -------
    ndarray (H, W, 3) float32
        Per pixel, the weighted mean of the finite pair estimates in the 5x5 window (clipped to the
        image) with weights ``exp(-(1 - n.n')/0.8 - |albedo - albedo'|^2/0.1^2 - ((z - z')/z)^2/0.05^2)``
        (1 at the pixel itself; 0 where a guide is not finite or one pixel is background, depth
        not finite, and the other not); float64 sums, at most float32 max. A pixel whose own
        estimate is not finite (non-finite halves) keeps it and is left out of its neighbours'
        windows.
    """
    pair = pair_variance(a, b)
    height, width = pair.shape[:2]
    finite = np.isfinite(pair).all(axis=-1)
    planes = []
    for name, components in (("normal", 3), ("albedo", 3), ("depth", 1)):
        value = (guides or {}).get(name)
        use = value is not None and np.shape(value)[:2] == (height, width)
        planes.append(use)
        planes.append(np.ascontiguousarray(value, np.float32).reshape(height, width, components) if use
                      else np.zeros((1, 1, components), np.float32))
    out = np.empty((height, width, 3), np.float32)
    with kernels.serial_below(height * width):
        _window_mean(pair, finite, *planes, RADIUS, out)
    return out


@njit(cache=True, inline="always")
def _distance(y: int, x: int, yy: int, xx: int, use_normal, normal, use_albedo, albedo, use_depth, depth) -> float:
    """The exponent of a neighbour's weight (``inf``: weight 0)."""
    d = 0.0
    if use_normal:
        dot = 0.0
        for c in range(3):
            dot += np.float64(normal[y, x, c]) * np.float64(normal[yy, xx, c])
        t = 1.0 - dot
        if not np.isfinite(t):
            return np.inf
        if t > 0.0:
            d += t / SIGMA_NORMAL
    if use_albedo:
        e = 0.0
        for c in range(3):
            diff = np.float64(albedo[y, x, c]) - np.float64(albedo[yy, xx, c])
            e += diff * diff
        if not np.isfinite(e):
            return np.inf
        d += e / (SIGMA_ALBEDO * SIGMA_ALBEDO)
    if use_depth:
        z0, z1 = np.float64(depth[y, x, 0]), np.float64(depth[yy, xx, 0])
        if np.isnan(z0) or np.isnan(z1) or np.isfinite(z0) != np.isfinite(z1):
            return np.inf
        if np.isfinite(z0):
            relative = (z1 - z0) / max(abs(z0), 1e-30)
            d += relative * relative / (SIGMA_DEPTH * SIGMA_DEPTH)
    return d


@njit(parallel=True, cache=True)
def _window_mean(pair, finite, use_normal, normal, use_albedo, albedo, use_depth, depth, radius, out):
    """``out[y, x]``: the weighted mean of the finite ``pair`` estimates in the window (see :func:`half_variance`)."""
    height, width = finite.shape
    for y in prange(height):
        for x in range(width):
            if not finite[y, x]:
                for c in range(3):
                    out[y, x, c] = pair[y, x, c]
                continue
            s0 = s1 = s2 = total = 0.0
            for yy in range(max(y - radius, 0), min(y + radius + 1, height)):
                for xx in range(max(x - radius, 0), min(x + radius + 1, width)):
                    if not finite[yy, xx]:
                        continue
                    weight = 1.0
                    if yy != y or xx != x:
                        weight = np.exp(-_distance(y, x, yy, xx, use_normal, normal, use_albedo, albedo,
                                                   use_depth, depth))
                    s0 += weight * pair[yy, xx, 0]
                    s1 += weight * pair[yy, xx, 1]
                    s2 += weight * pair[yy, xx, 2]
                    total += weight
            out[y, x, 0] = min(s0 / total, FLOAT32_MAX)  # total >= 1: the pixel itself
            out[y, x, 1] = min(s1 / total, FLOAT32_MAX)
            out[y, x, 2] = min(s2 / total, FLOAT32_MAX)
