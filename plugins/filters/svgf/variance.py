"""Luminance variance: temporal from the moments, spatial (7x7) while history is short.

Schied et al. 2017, section 4.2: ``sigma^2 = mu2 - mu1^2`` from the accumulated moments once a
pixel has ``variance_frames`` frames of history; before that the moments are averaged over a
7x7 neighbourhood with depth and normal edge-stopping weights, evaluated as in the à-trous
iterations: ``w_z w_n = expneg(-(depth distance + sigma_n (-ln n_p . n_q)))`` with
:func:`.weights.expneg` and :func:`.weights.neg_log_series`. Variances are float64 (squared
luminances of large inputs overflow float32) and clamped at zero.
"""

from __future__ import annotations

from numba import njit

from .weights import VAR_MAX, depth_distance, expneg, gauss3_tap, neg_log_series

#: radius of the spatial variance estimate (7x7)
SPATIAL_RADIUS = 3


@njit(cache=True, inline="always")
def variance_pixel(i, j, mom, hist, valid, depth, normal, grad, variance_frames,
                   sigma_z, sigma_n, depth_eps, var):
    """Luminance variance of every signal at pixel (i, j).

    Parameters
    ----------
    mom : ndarray (S, 2, H, W) float64
        Accumulated first and second luminance moments.
    hist : ndarray (H, W) float32
        History length.
    valid, depth, normal, grad : ndarray
        Planar G-buffer and depth gradient.
    variance_frames : float
        Spatial estimate where ``hist < variance_frames``.
    sigma_z, sigma_n, depth_eps : float
        Edge-stopping parameters (see :mod:`.weights`).
    var : ndarray (S, H, W) float64
        Output.
    """
    nsig = mom.shape[0]
    if valid[i, j] == 0:
        for s in range(nsig):
            var[s, i, j] = 0.0
        return
    if hist[i, j] >= variance_frames:
        for s in range(nsig):
            m1 = mom[s, 0, i, j]
            var[s, i, j] = max(mom[s, 1, i, j] - m1 * m1, 0.0)
        return
    h = valid.shape[0]
    w = valid.shape[1]
    zp = depth[i, j]
    gx = grad[0, i, j]
    gy = grad[1, i, j]
    nx = normal[0, i, j]
    ny = normal[1, i, j]
    nz = normal[2, i, j]
    for s in range(nsig):
        wsum = 0.0
        s1 = 0.0
        s2 = 0.0
        for dy in range(-SPATIAL_RADIUS, SPATIAL_RADIUS + 1):
            y = i + dy
            if y < 0 or y >= h:
                continue
            for dx in range(-SPATIAL_RADIUS, SPATIAL_RADIUS + 1):
                x = j + dx
                if x < 0 or x >= w or valid[y, x] != valid[i, j]:  # another surface kind: no weight
                    continue
                if dx == 0 and dy == 0:
                    wt = 1.0
                else:
                    d = nx * normal[0, y, x] + ny * normal[1, y, x] + nz * normal[2, y, x]
                    if d <= 0.0:
                        continue
                    dist = min(depth_distance(zp, depth[y, x], gx, gy, dx, dy, sigma_z, depth_eps), 1024.0)
                    wt = expneg(-(dist + sigma_n * neg_log_series(d)))
                wsum += wt
                s1 += wt * mom[s, 0, y, x]
                s2 += wt * mom[s, 1, y, x]
        m1 = s1 / wsum
        var[s, i, j] = max(s2 / wsum - m1 * m1, 0.0)


@njit(cache=True, inline="always")
def prefiltered_variance(var, valid, s, i, j):
    """3x3 Gaussian blur of signal ``s``'s variance at valid pixel (i, j), over the neighbours of its
    kind (``valid``: demodulated or not, :mod:`.modulation`).

    Parameters
    ----------
    var : ndarray (S, H, W) float64
    valid : ndarray (H, W) uint8
    s, i, j : int
        Signal, row, column.

    Returns
    -------
    float
        The blurred variance (each at most ``VAR_MAX``; the weights of the valid neighbours
        renormalised).
    """
    h = valid.shape[0]
    w = valid.shape[1]
    wsum = 0.0
    acc = 0.0
    for dy in range(-1, 2):
        y = i + dy
        if y < 0 or y >= h:
            continue
        for dx in range(-1, 2):
            x = j + dx
            if x < 0 or x >= w or valid[y, x] != valid[i, j]:
                continue
            wt = gauss3_tap(dy) * gauss3_tap(dx)
            wsum += wt
            acc += wt * min(var[s, y, x], VAR_MAX)
    return acc / wsum if wsum > 0.0 else 0.0
