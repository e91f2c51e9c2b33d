"""Row-vectorized luminance variance for the ``cpu`` backend.

The same estimate as :func:`plugins.filters.svgf.variance.variance_pixel`: temporal
``mu2 - mu1^2`` where the history is long enough, else the 7x7 depth- and normal-weighted
spatial estimate. Rows without a short-history pixel skip the spatial sums; other rows sweep
the 49 taps with branch-free float32 weights (as the à-trous iterations) into float64 sums.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .variance import SPATIAL_RADIUS
from .weights import expneg

_TINY = np.float32(1e-20)
_ARG_MAX = np.float32(1024.0)


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _spatial_run(i, a, b, mom, valid, depth, normal, grad, sz, de, sigma_n, sigma_n_int,
                 wsum, s1, s2, base, wt):
    """7x7 weighted sums of the moments for pixels ``a <= j < b`` of row ``i``."""
    nsig = mom.shape[0]
    h = valid.shape[0]
    w = valid.shape[1]
    for dy in range(-SPATIAL_RADIUS, SPATIAL_RADIUS + 1):
        y = i + dy
        if y < 0 or y >= h:
            continue
        dyf = np.float32(dy)
        for dx in range(-SPATIAL_RADIUS, SPATIAL_RADIUS + 1):
            j0 = max(a, -dx)
            j1 = min(b, w - dx)
            if j0 >= j1:
                continue
            n = j1 - j0
            q0, q1 = j0 + dx, j1 + dx
            wr = wt[j0:j1]
            vq = valid[y, q0:q1]
            if dx == 0 and dy == 0:
                for k in range(n):
                    wr[k] = np.float32(vq[k])
            else:
                br = base[j0:j1]
                n0p, n1p, n2p = normal[0, i, j0:j1], normal[1, i, j0:j1], normal[2, i, j0:j1]
                n0q, n1q, n2q = normal[0, y, q0:q1], normal[1, y, q0:q1], normal[2, y, q0:q1]
                for k in range(n):
                    d = n0p[k] * n0q[k] + n1p[k] * n1q[k] + n2p[k] * n2q[k]
                    br[k] = min(max(d, np.float32(0.0)), np.float32(1.0))
                zpr = depth[i, j0:j1]
                zqr = depth[y, q0:q1]
                gxr = grad[0, i, j0:j1]
                gyr = grad[1, i, j0:j1]
                dxf = np.float32(dx)
                for k in range(n):
                    zp = zpr[k]
                    den = sz * abs(gxr[k] * dxf + gyr[k] * dyf) + de * abs(zp) + _TINY
                    dist = min(abs(zp - zqr[k]) / den, _ARG_MAX)
                    wr[k] = np.float32(vq[k]) * expneg(-dist)
                e = sigma_n_int
                if e < 0:
                    for k in range(n):
                        wr[k] *= np.float32(br[k] ** sigma_n)
                while e > 0:
                    if e & 1:
                        for k in range(n):
                            wr[k] *= br[k]
                    e >>= 1
                    if e > 0:
                        for k in range(n):
                            br[k] *= br[k]
            ws = wsum[j0:j1]
            for k in range(n):
                ws[k] += wr[k]
            for s in range(nsig):
                a1 = s1[s, j0:j1]
                a2 = s2[s, j0:j1]
                m1 = mom[s, 0, y, q0:q1]
                m2 = mom[s, 1, y, q0:q1]
                for k in range(n):
                    a1[k] += wr[k] * m1[k]
                for k in range(n):
                    a2[k] += wr[k] * m2[k]


@njit(parallel=True, cache=True, fastmath=True, error_model="numpy")
def variance_rows(mom, hist, valid, depth, normal, grad, variance_frames, sigma_z, sigma_n,
                  sigma_n_int, depth_eps, var):
    """Luminance variance of every signal (arguments as ``variance_pixel``, no i, j)."""
    nsig = mom.shape[0]
    h = valid.shape[0]
    w = valid.shape[1]
    sz = np.float32(sigma_z)
    de = np.float32(depth_eps)
    for r in prange(h):
        i = np.int64(r)  # prange indices may be unsigned
        short = False
        for j in range(w):
            if valid[i, j] != 0:
                if hist[i, j] >= variance_frames:
                    for s in range(nsig):
                        m1 = mom[s, 0, i, j]
                        var[s, i, j] = max(mom[s, 1, i, j] - m1 * m1, 0.0)
                else:
                    short = True
            else:
                for s in range(nsig):
                    var[s, i, j] = 0.0
        if not short:
            continue
        wsum = np.zeros(w, np.float64)
        s1 = np.zeros((nsig, w), np.float64)
        s2 = np.zeros((nsig, w), np.float64)
        base = np.empty(w, np.float32)
        wt = np.empty(w, np.float32)
        # sweep each run [a, b) of consecutive short-history pixels only (a camera pan adds a
        # thin column of them to every row)
        b = 0
        while b < w:
            a = b
            while a < w and not (valid[i, a] != 0 and hist[i, a] < variance_frames):
                a += 1
            if a >= w:
                break
            b = a
            while b < w and valid[i, b] != 0 and hist[i, b] < variance_frames:
                b += 1
            _spatial_run(i, a, b, mom, valid, depth, normal, grad, sz, de, sigma_n, sigma_n_int,
                         wsum, s1, s2, base, wt)
        for j in range(w):
            if valid[i, j] != 0 and hist[i, j] < variance_frames:
                inv = 1.0 / wsum[j]
                for s in range(nsig):
                    m1 = s1[s, j] * inv
                    var[s, i, j] = max(s2[s, j] * inv - m1 * m1, 0.0)
