"""One edge-avoiding à-trous iteration of SVGF (Schied et al. 2017, section 4.3).

A 5x5 B3-spline kernel with holes (step ``2^i``), weighted by

* ``w_z = exp(-|z_p - z_q| / (sigma_z |grad z(p) . (p - q)| + eps))``,
* ``w_n = max(0, n_p . n_q) ^ sigma_n`` (as ``exp(sigma_n ln d)``, :func:`.weights.neg_log_series`),
* ``w_l = exp(-|l_p - l_q| / (sigma_l sqrt(g3x3(Var(l_p))) + eps))``,

(the depth and luminance exponentials evaluated together by :func:`.weights.expneg`),
with the variance prefiltered by a 3x3 Gaussian (:func:`.variance.prefiltered_variance`),
and the variance is filtered alongside: ``Var' = sum (h w)^2 Var / (sum h w)^2``. The centre
tap always has weight ``h(0)^2 > 0``, so every normalisation is safe. Background pixels are
skipped (neither written as centre nor used as taps). Variances, luminances and the luminance
weight's inverse scale are bounded as in the CPU backend's float32 pool (:mod:`.weights`).
"""

from __future__ import annotations

import math

from numba import njit

from .variance import prefiltered_variance
from .weights import INV_MAX, LUM_MAX, VAR_MAX, b3_tap, depth_distance, expneg, luminance, neg_log_series


@njit(cache=True, inline="always")
def _bounded_luminance(sig, s, y, x):
    """Luminance of signal ``s`` at (y, x), limited to +-LUM_MAX."""
    return min(max(luminance(sig[s, 0, y, x], sig[s, 1, y, x], sig[s, 2, y, x]), -LUM_MAX), LUM_MAX)


@njit(cache=True, inline="always")
def atrous_pixel(i, j, step, sig, var, valid, depth, normal, grad,
                 sigma_z, sigma_n, sigma_l, depth_eps, lum_eps, sig_out, var_out):
    """Filter pixel (i, j) of every signal with one à-trous iteration.

    Parameters
    ----------
    step : int
        Hole size ``2^iteration`` in pixels.
    sig : ndarray (S, 3, H, W) float32
        Demodulated signals of the previous iteration (S is 1 or 2).
    var : ndarray (S, H, W) float64
        Their luminance variance.
    valid, depth, normal, grad : ndarray
        Planar G-buffer and depth gradient.
    sigma_z, sigma_n, sigma_l, depth_eps, lum_eps
        Edge-stopping parameters.
    sig_out, var_out : ndarray
        Outputs, shaped as ``sig`` and ``var``.
    """
    nsig = sig.shape[0]
    if valid[i, j] == 0:
        for s in range(nsig):
            for c in range(3):
                sig_out[s, c, i, j] = 0.0
            var_out[s, i, j] = 0.0
        return
    two = nsig == 2
    h = valid.shape[0]
    w = valid.shape[1]
    zp = depth[i, j]
    gx = grad[0, i, j]
    gy = grad[1, i, j]
    nx = normal[0, i, j]
    ny = normal[1, i, j]
    nz = normal[2, i, j]
    lp0 = _bounded_luminance(sig, 0, i, j)
    il0 = min(1.0 / (sigma_l * math.sqrt(prefiltered_variance(var, valid, 0, i, j)) + lum_eps), INV_MAX)
    lp1 = 0.0
    il1 = 0.0
    if two:
        lp1 = _bounded_luminance(sig, 1, i, j)
        il1 = min(1.0 / (sigma_l * math.sqrt(prefiltered_variance(var, valid, 1, i, j)) + lum_eps), INV_MAX)
    w0 = 0.0
    r0 = 0.0
    g0 = 0.0
    b0 = 0.0
    v0 = 0.0
    w1 = 0.0
    r1 = 0.0
    g1 = 0.0
    b1 = 0.0
    v1 = 0.0
    for ky in range(-2, 3):
        y = i + ky * step
        if y < 0 or y >= h:
            continue
        hy = b3_tap(ky)
        for kx in range(-2, 3):
            x = j + kx * step
            if x < 0 or x >= w or valid[y, x] != valid[i, j]:  # background, or the other kind of pixel
                continue
            geo = hy * b3_tap(kx)
            dist = 0.0
            if kx != 0 or ky != 0:
                d = nx * normal[0, y, x] + ny * normal[1, y, x] + nz * normal[2, y, x]
                if d <= 0.0:
                    continue
                # w_z w_n = exp(-(depth distance + sigma_n (-ln d)))
                dist = (min(depth_distance(zp, depth[y, x], gx, gy, kx * step, ky * step, sigma_z, depth_eps),
                            1024.0) + sigma_n * neg_log_series(d))
            q0 = sig[0, 0, y, x]
            q1 = sig[0, 1, y, x]
            q2 = sig[0, 2, y, x]
            centre = kx == 0 and ky == 0
            wt = geo if centre else geo * expneg(-(dist + abs(lp0 - _bounded_luminance(sig, 0, y, x)) * il0))
            w0 += wt
            r0 += wt * q0
            g0 += wt * q1
            b0 += wt * q2
            v0 += wt * wt * min(var[0, y, x], VAR_MAX)
            if two:
                q0 = sig[1, 0, y, x]
                q1 = sig[1, 1, y, x]
                q2 = sig[1, 2, y, x]
                wt = geo if centre else geo * expneg(-(dist + abs(lp1 - _bounded_luminance(sig, 1, y, x)) * il1))
                w1 += wt
                r1 += wt * q0
                g1 += wt * q1
                b1 += wt * q2
                v1 += wt * wt * min(var[1, y, x], VAR_MAX)
    inv = 1.0 / w0
    sig_out[0, 0, i, j] = r0 * inv
    sig_out[0, 1, i, j] = g0 * inv
    sig_out[0, 2, i, j] = b0 * inv
    var_out[0, i, j] = v0 * inv * inv
    if two:
        inv = 1.0 / w1
        sig_out[1, 0, i, j] = r1 * inv
        sig_out[1, 1, i, j] = g1 * inv
        sig_out[1, 2, i, j] = b1 * inv
        var_out[1, i, j] = v1 * inv * inv
