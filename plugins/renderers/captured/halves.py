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
        ``normal`` (H, W, 3), ``albedo`` (H, W, 3), ``depth`` (H, W), whichever the capture has;
        without any the window is a plain 5x5 box.

    Returns
    -------
    ndarray (H, W, 3) float32
        Per pixel, the weighted mean of the finite pair estimates in the 5x5 window (clipped to the
        image) with weights ``exp(-(1 - n.n')/0.8 - |albedo - albedo'|^2/0.1^2 - ((z - z')/z)^2/0.05^2)``
        (1 at the pixel itself); float64 sums, at most float32 max. A pixel whose own estimate is not
        finite (non-finite halves) keeps it and is left out of its neighbours' windows.
    """
    pair = pair_variance(a, b)
    height, width = pair.shape[:2]
    finite = np.isfinite(pair).all(axis=-1)
    keys = _guide_keys(guides or {}, (height, width))
    total = np.zeros_like(pair)
    weights = np.zeros((height, width))
    for dy in range(-RADIUS, RADIUS + 1):
        for dx in range(-RADIUS, RADIUS + 1):
            here, there = _overlap(dy, height), _overlap(dx, width)
            target = (slice(*here[0]), slice(*there[0]))  # pixels whose window holds the neighbour
            source = (slice(*here[1]), slice(*there[1]))  # the neighbours
            weight = finite[source].astype(np.float64)
            if dy or dx:
                weight = weight * _guide_weight(keys, target, source)
            total[target] += weight[..., None] * np.where(finite[source][..., None], pair[source], 0.0)
            weights[target] += weight
    with np.errstate(invalid="ignore", divide="ignore"):
        out = total / np.where(weights > 0.0, weights, 1.0)[..., None]
    out = np.where(finite[..., None], np.minimum(out, FLOAT32_MAX), pair)
    return out.astype(np.float32)


def _overlap(shift: int, size: int) -> tuple:
    """Index ranges (target, source) of pixels ``i`` and their neighbours ``i + shift`` inside ``size``."""
    if shift >= 0:
        return (0, max(size - shift, 0)), (shift, max(size, shift))
    return (-shift, max(size, -shift)), (0, max(size + shift, 0))


def _guide_keys(guides: dict, shape: tuple) -> dict:
    """Sanitised guide planes (float64): non-finite normals and albedos become NaN flags, depth keeps
    background (not finite) apart."""
    keys = {}
    for name in ("normal", "albedo"):
        if guides.get(name) is not None:
            value = np.asarray(guides[name], np.float64)
            if value.shape[:2] == shape:
                keys[name] = np.where(np.isfinite(value).all(axis=-1, keepdims=True), value, np.nan)
    if guides.get("depth") is not None:
        depth = np.asarray(guides["depth"], np.float64)
        if depth.shape[:2] == shape:
            keys["depth"] = depth.reshape(shape)
    return keys


def _guide_weight(keys: dict, target: tuple, source: tuple) -> np.ndarray:
    """exp(-distance) between the guides of the pixels ``target`` and their neighbours ``source``;
    0 where a guide is not finite, or one of the two pixels is background and the other not."""
    distance = 0.0
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        if "normal" in keys:
            n = keys["normal"]
            dot = np.sum(n[target] * n[source], axis=-1)
            distance = distance + np.maximum(1.0 - dot, 0.0) / SIGMA_NORMAL
        if "albedo" in keys:
            alb = keys["albedo"]
            distance = distance + np.sum((alb[target] - alb[source]) ** 2, axis=-1) / SIGMA_ALBEDO**2
        if "depth" in keys:
            z0, z1 = keys["depth"][target], keys["depth"][source]
            both = np.isfinite(z0) & np.isfinite(z1)
            relative = np.where(both, (z1 - z0) / np.maximum(np.abs(z0), 1e-30), 0.0)
            apart = np.where(np.isfinite(z0) == np.isfinite(z1), relative**2 / SIGMA_DEPTH**2, np.inf)
            apart = np.where(np.isnan(z0) | np.isnan(z1), np.inf, apart)
            distance = distance + apart
        weight = np.exp(-np.asarray(distance, np.float64))
    return np.where(np.isnan(weight), 0.0, weight)
